"""Does `diagnose --domain pneumatics` name what was hidden on a simulator it was not tuned on?
(issue #31)

Two generators of the same robot (experiments/pneumatic_robot: 2 joints x 2 chambers, 60-s logs):
``offsim``, the independent thin-plate generator of experiments/pneumatic_generator.py, and
``project``, the project's simulator (``diegocal simulate pneumatics``). Each gets ``--logs`` logs
per effect (valve_delay, chamber_leak, supply_droop, pressure_offset; chamber and size drawn from
the seed, sizes below) and ``--logs`` clean logs. Every log is diagnosed with the defaults a user
gets (all four chambers). A hidden effect is *named* when the log's top finding is its cause on
its chamber; a clean log is a *false alarm* when it gives any finding; ``wrong`` counts findings
on the chambers of effect logs that hide nothing.

Sizes. offsim: the generator's ranges (valve delay 40-50 ms, leak orifice 0.35-0.8e-6 m²,
supply-line orifice 0.8-1.6e-6 m², offset ±9-13 kPa). project: delay, leak and offset alike;
supply droop 60-140 kPa per g/s (its own unit: the sag per supply flow); offsets positive (its
``--effect`` takes positive sizes). The project's simulator
integrates the logs of one effect on one chamber together (``sessions``, one size per group).

``--new-session K``: for K named logs per effect, the diagnosed (extended) model and the
baseline predict another session of the same robot (same valves, same effect, another seed) with
resets every 2 s; the share of the effect's error removed against the noise-free reading is
``(E_base² - E_ext²) / (E_base² - E_ref²)``, E_ref the baseline fitted on the log's clean twin
predicting the new session's clean twin (the model's own error). Median and worst are printed;
a log where the effect costs less than a tenth of E_base² beyond E_ref is n/a (:data:`MIN_COST`).

Logs are cached under ``--cache`` (generation dominates the cost). The bench reads ``/truth`` to
judge; the diagnosis never sees it.

    .venv/bin/python bench/bench_pneumatic_offsim.py --logs 12 --jobs 2 --cache /tmp/offsim
    .venv/bin/python bench/bench_pneumatic_offsim.py --quick     # a smoke run (tests)
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from experiments import pneumatic_generator as gen  # noqa: E402

CAUSES = gen.CAUSES
GENERATORS = ("offsim", "project")
PROJECT_SIZES = {
    "valve_delay": (0.040, 0.050),
    "chamber_leak": (0.35e-6, 0.8e-6),
    "supply_droop": (60.0, 140.0),
    "pressure_offset": (9.0, 13.0),
}


@dataclass(frozen=True)
class Case:
    generator: str
    cause: str | None
    chamber: str | None
    size: float
    seed: int
    group: int = 0  # project: logs of one group are simulated together (one size)


@dataclass(frozen=True)
class Settings:
    duration: float = 60.0
    substeps: int = 20


@dataclass(frozen=True)
class Outcome:
    case: Case
    top: str
    findings: tuple
    gain: float
    seconds: float
    values: tuple = ()
    error: str = ""

    @property
    def named(self) -> bool:
        c = self.case
        return c.cause is not None and self.top == f"{c.cause}:{c.chamber}"

    @property
    def wrong(self) -> int:
        """Findings on chambers that hide nothing."""
        return sum(1 for f in self.findings if f.split(":")[1] != self.case.chamber)


def plan(n_logs: int, seed: int, generators, chambers) -> list[Case]:
    """``n_logs`` logs per effect (chambers in turn, sizes drawn) and ``n_logs`` clean ones."""
    out = []
    for g in generators:
        ss = np.random.SeedSequence([seed, GENERATORS.index(g)])  # the same logs whichever run
        seeds = ss.generate_state(5 * n_logs)
        rng = np.random.default_rng(ss.spawn(1)[0])
        k = 0
        for c_i, cause in enumerate(CAUSES):
            lo, hi = (gen.SIZES if g == "offsim" else PROJECT_SIZES)[cause]
            size = None
            for i in range(n_logs):
                chamber = chambers[(i + c_i) % len(chambers)]
                # project: one group per chamber (its logs share a size and one integration)
                group = c_i * len(chambers) + (i + c_i) % len(chambers)
                if g == "offsim" or i < len(chambers):
                    size = float(rng.uniform(lo, hi))
                    if cause == "pressure_offset" and g == "offsim":  # project: sizes are positive
                        size *= float(rng.choice([-1.0, 1.0]))
                if g == "project":
                    size = _group_size(out, g, group, size)
                out.append(Case(g, cause, chamber, size, int(seeds[k]), group))
                k += 1
        for _ in range(n_logs):
            out.append(Case(g, None, None, 0.0, int(seeds[k]), -1))
            k += 1
    return out


def _group_size(cases, generator, group, size):
    same = [c.size for c in cases if c.generator == generator and c.group == group]
    return same[0] if same else size


# ----------------------------------------------------------------------------- logs
def _path(cache: Path | None, case: Case, settings: Settings, tag: str = "") -> Path | None:
    if cache is None:
        return None
    name = f"{case.generator}_{case.cause or 'clean'}_{case.chamber or '-'}_{case.size:.6g}_{case.seed}"
    return cache / f"{name}_{settings.duration:g}s_{settings.substeps}{tag}.h5"


def make_logs(cases, settings: Settings, cache: Path | None, robot, clean: bool = False, jobs: int = 1) -> list:
    """The log of every case (``clean``: its clean twin), cached."""
    from diegocal.io import load_log, save_log

    tag = "_clean" if clean else ""
    logs = [None] * len(cases)
    todo = []
    for i, c in enumerate(cases):
        p = _path(cache, c, settings, tag)
        if p is not None and p.exists():
            logs[i] = load_log(p)
        else:
            todo.append(i)
    groups: dict = {}
    for i in todo:
        c = cases[i]
        key = ("offsim", i // 16) if c.generator == "offsim" else ("project", c.group, c.size)
        groups.setdefault(key, []).append(i)
    tasks = [([cases[i] for i in idx], settings, clean) for idx in groups.values()]
    for idx, out in zip(groups.values(), _imap(_simulate, tasks, jobs), strict=True):
        for i, log in zip(idx, out, strict=True):  # saved as each group is done
            logs[i] = log
            p = _path(cache, cases[i], settings, tag)
            if p is not None:
                p.parent.mkdir(parents=True, exist_ok=True)
                save_log(log, p)
    return logs


def _imap(fn, tasks, jobs):
    """fn over tasks in order, yielding each result as it is ready."""
    if jobs > 1 and len(tasks) > 1:
        with ProcessPoolExecutor(max_workers=jobs) as pool:
            yield from pool.map(fn, tasks)
    else:
        yield from (fn(t) for t in tasks)


def _map(fn, tasks, jobs):
    return list(_imap(fn, tasks, jobs))


def _simulate(task):
    cases, settings, clean = task
    if cases[0].generator == "offsim":
        opts = [
            gen.GeneratorOptions(
                duration=settings.duration,
                substeps=settings.substeps,
                seed=c.seed,
                effects=() if (clean or c.cause is None) else (gen.Effect(c.cause, c.chamber, c.size),),
            )
            for c in cases
        ]
        return gen.generate_many(opts)
    from diegocal.robot import load_robot
    from diegocal.sim.effects import parse_effects
    from diegocal.sim.pneumatics import PneumaticSimOptions, simulate_pneumatics

    robot = load_robot(gen.ROBOT_DIR)
    c = cases[0]
    effects = () if (clean or c.cause is None) else parse_effects([f"{c.cause}:{c.chamber}={c.size:.6g}"])
    # one integration for the group: sessions seeded by the first case (the others' seeds name them)
    log = simulate_pneumatics(
        robot,
        PneumaticSimOptions(
            duration=settings.duration, substeps=settings.substeps, effects=effects, seed=c.seed, sessions=len(cases)
        ),
    )
    n = int(round(settings.duration * 100.0)) + 1
    return [log.slice(k * n, (k + 1) * n) for k in range(len(cases))]


# ----------------------------------------------------------------------------- diagnosis
def diagnose_one(args) -> Outcome:
    case, log = args
    from diegocal.diagnose import DiagnoseOptions, diagnose
    from diegocal.errors import DiegocalError
    from diegocal.robot import load_robot

    robot = load_robot(gen.ROBOT_DIR)
    start = time.perf_counter()
    try:
        result = diagnose(log, robot, DiagnoseOptions(domain="pneumatics"))
    except DiegocalError as exc:
        return Outcome(case, "", (), float("nan"), time.perf_counter() - start, error=str(exc))
    found = tuple(f"{f.cause}:{f.channel}" for f in result.findings)
    gain = float(result.findings[0].gain().get("reduction", np.nan)) if found else float("nan")
    values = tuple(float(v) for v in result.findings[0].term.values) if found else ()
    return Outcome(case, found[0] if found else "", found, gain, time.perf_counter() - start, values)


def table(outcomes) -> str:
    rows = [
        "| generator | cause | logs | named | false alarms | findings on clean chambers | what else was named |",
        "|---|---|---|---|---|---|---|",
    ]
    for g in GENERATORS:
        mine = [o for o in outcomes if o.case.generator == g]
        if not mine:
            continue
        for cause in (*CAUSES, None):
            grp = [o for o in mine if o.case.cause == cause]
            if not grp:
                continue
            n = len(grp)
            other = {}
            for o in grp:
                if not o.named and o.top:
                    here = o.top.endswith(f":{o.case.chamber}") or cause is None
                    k = o.top.split(":")[0] + ("" if here else " (other chamber)")
                    other[k] = other.get(k, 0) + 1
                elif not o.top and cause is not None:
                    other["nothing"] = other.get("nothing", 0) + 1
            named = "" if cause is None else f"{sum(o.named for o in grp)}/{n}"
            alarms = f"{sum(bool(o.findings) for o in grp)}/{n}" if cause is None else ""
            wrong = sum(o.wrong for o in grp)
            rows.append(
                f"| {g} | {cause or '(clean)'} | {n} | {named} | {alarms} | {wrong} | "
                + ", ".join(f"{k} {v}" for k, v in sorted(other.items()))
                + " |"
            )
        hid = [o for o in mine if o.case.cause]
        cln = [o for o in mine if not o.case.cause]
        clean_chambers = 3 * len(hid) + 4 * len(cln)
        alarms_ch = sum(o.wrong for o in hid) + sum(len(o.findings) for o in cln)
        rows.append(
            f"| **{g}** | all | {len(hid)} + {len(cln)} | **{sum(o.named for o in hid) / max(len(hid), 1):.0%}** | "
            f"**{sum(bool(o.findings) for o in cln) / max(len(cln), 1):.0%}** | "
            f"{alarms_ch}/{clean_chambers} = {alarms_ch / max(clean_chambers, 1):.1%} | |"
        )
    return "\n".join(rows)


# ----------------------------------------------------------------------------- a new session
def new_session(cases, logs, outcomes, settings, cache, per_effect: int, jobs: int):
    """Item 5 of issue #31 (module docstring): per effect, the share of its error removed."""
    chosen = []
    for g in GENERATORS:
        for cause in CAUSES:
            hits = [i for i, (c, o) in enumerate(zip(cases, outcomes, strict=True))
                    if c.generator == g and c.cause == cause and o.named]
            chosen += hits[:per_effect]
    if not chosen:
        return []
    # clean twins: a project log's twin is its whole group simulated again without the effect
    members = sorted({j for i in chosen for j, c in enumerate(cases)
                      if j == i or (c.generator == "project" and c.group == cases[i].group and c.cause)})
    twins = dict(zip(members, make_logs([cases[j] for j in members], settings, cache, None, clean=True, jobs=jobs),
                     strict=True))
    # another session: the same effect (chamber, size), another seed, simulated on its own
    new = [replace(cases[i], seed=cases[i].seed + 7919, group=10_000 + k) for k, i in enumerate(chosen)]
    new_logs = make_logs(new, settings, cache, None, jobs=jobs)
    new_twins = make_logs(new, settings, cache, None, clean=True, jobs=jobs)
    tasks = [(cases[i], logs[i], twins[i], a, b) for i, a, b in zip(chosen, new_logs, new_twins, strict=True)]
    return _map(_share, tasks, jobs)


#: The effect's cost on the new session (E_base² − E_ref²) must be at least this share of E_base² for
#: a share removed to mean anything: below it the model's own multi-step error (E_ref, a baseline
#: fitted on the clean twin) is as large as the effect's, and the ratio divides noise by noise.
MIN_COST = 0.1


def _share(task):
    from diegocal.diagnose import DiagnoseOptions, diagnose
    from diegocal.pneumatic import chamber_data, predict_with_resets
    from diegocal.robot import load_robot

    case, log, twin, new_log, new_twin = task
    robot = load_robot(gen.ROBOT_DIR)
    result = diagnose(log, robot, DiagnoseOptions(domain="pneumatics", chambers=(case.chamber,)))
    unit, adapter = result.units[0], result.adapters[0]
    train = result.blocks.mask("train")
    base = adapter.fit((), train).params
    ref_adapter = type(adapter)(chamber_data(twin, robot.sensors, case.chamber), adapter.volume_sensor)
    ref = ref_adapter.fit((), train).params

    def err(params, lg):
        d = chamber_data(lg, robot.sensors, case.chamber)
        truth = _reading(lg, case.chamber)
        return float(np.sqrt(np.mean((predict_with_resets(params, d) - truth) ** 2)))

    e_base, e_ext, e_ref = err(base, new_log), err(unit.fitted.params, new_log), err(ref, new_twin)
    cost = e_base**2 - e_ref**2
    share = (e_base**2 - e_ext**2) / cost if cost > MIN_COST * e_base**2 else float("nan")
    return case, e_base, e_ext, e_ref, share


def _reading(log, chamber):
    """The noise-free reading of ``chamber`` (the true pressure plus any sensor offset)."""
    sig = log.truth.signals
    if "reading" in sig:
        return sig["reading"].column(chamber)
    off = sum(
        e["values"]["offset"] for e in log.truth.effects if e["cause"] == "pressure_offset" and e["channel"] == chamber
    )
    return sig["pressure"].column(chamber) + off


def share_table(rows) -> str:
    out = ["| generator | cause | logs | E_base | E_ext | E_ref (kPa, medians) | share removed: median | worst |",
           "|---|---|---|---|---|---|---|---|"]
    for g in GENERATORS:
        for cause in CAUSES:
            r = [x for x in rows if x[0].generator == g and x[0].cause == cause]
            if not r:
                continue
            s = np.array([x[4] for x in r])
            ok = s[np.isfinite(s)]
            shares = f"{np.median(ok):.0%} | {ok.min():.0%}" if ok.size else "n/a | n/a"
            if ok.size < s.size:
                shares += f" ({s.size - ok.size} n/a: the effect costs less than the model's own error)"
            out.append(
                f"| {g} | {cause} | {len(r)} | {np.median([x[1] for x in r]):.2f} | "
                f"{np.median([x[2] for x in r]):.2f} | {np.median([x[3] for x in r]):.2f} | {shares} |"
            )
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--logs", type=int, default=12, help="logs per effect, and as many clean, per generator")
    ap.add_argument("--seed", type=int, default=31)
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--cache", type=Path, default=None, help="keep the generated logs here")
    ap.add_argument("--generator", action="append", choices=GENERATORS, help="default: both")
    ap.add_argument("--new-session", type=int, default=0, metavar="K", help="item 5 on K named logs per effect")
    ap.add_argument("--quick", action="store_true", help="1 log per effect, 15-s logs, 5 sub-steps (a smoke run)")
    ap.add_argument("--verbose", action="store_true", help="one line per log")
    args = ap.parse_args(argv)
    settings = Settings(15.0, 5) if args.quick else Settings()
    n_logs = 1 if args.quick else args.logs
    generators = tuple(args.generator or GENERATORS)
    chambers = gen.load_chambers().names
    cases = plan(n_logs, args.seed, generators, chambers)
    print(
        f"bench_pneumatic_offsim: seed {args.seed}, {n_logs} logs per effect + {n_logs} clean per generator, "
        f"{settings.duration:g}-s logs, {settings.substeps} sub-steps/tick, load {os.getloadavg()[0]:.1f}"
    )
    t0 = time.perf_counter()
    logs = make_logs(cases, settings, args.cache, None, jobs=args.jobs)
    t1 = time.perf_counter()
    outcomes = _map(diagnose_one, list(zip(cases, logs, strict=True)), args.jobs)
    t2 = time.perf_counter()
    if args.verbose:
        for o in outcomes:
            c = o.case
            print(
                f"{c.generator:8s} {str(c.cause):16s} {str(c.chamber):14s} size {c.size:<10.4g} seed {c.seed:<11d} "
                f"top {o.top or '-':32s} {np.round(o.values, 4)} gain {o.gain:5.2f} all {list(o.findings)} {o.error}"
            )
    print(table(outcomes))
    print(
        f"generation {t1 - t0:.0f} s wall, diagnosis {t2 - t1:.0f} s wall "
        f"(median {np.median([o.seconds for o in outcomes]):.1f} s per log), --jobs {args.jobs}"
    )
    if args.new_session:
        rows = new_session(cases, logs, outcomes, settings, args.cache, args.new_session, args.jobs)
        print(share_table(rows))
    print(f"load average at the end: {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
