"""Does `diagnose --domain kinematics` name what was hidden on a generator it was not tuned on,
and does the extended model carry over to another session? (issue #31, items 1, 4 and 7)

Two generators of the same robot directory (``--robot``: the generator's blind iCub, 32 rotary
pots and 16 markers on every other link, mocap frame unknown; or its UR5): ``offsim``, the
independent generator of experiments/kinematics_generator.py (minimum-jerk motion, quantised
pots, anisotropic and partly slow marker noise, the effects in their physical form), and
``project``, the project's simulator (``diegocal simulate kinematics``). Each gets ``--logs``
logs per effect (time_offset 20-30 ms, backlash, sensor_nonlinearity, marker_slip,
link_offset; channel and size drawn from the seed, the same for both generators) and ``--logs``
clean logs, diagnosed with the defaults a user gets. Per effect: *named* when the top finding
is the cause on its channel (a link offset: the joint; or on a channel the finding says the data
cannot tell from it), *anywhere* when some finding is; a clean
log gives a *false alarm* when it gives any finding. Sizes: offsim's :data:`SIZES`; the project's
simulator gets the same numbers in its own units (the dead band's and the transfer curve's width
on the reading, in V; a link lengthened along the link).

``--new-session`` (item 4): for every named offsim log, three
calibrations fitted on the diagnosis's training blocks, the baseline (STAC), the extended model
(the diagnosis's) and the *oracle* (the baseline with the effect's exact term: its true cause,
channel, dead band, clock shift start, slip time, values fitted), predict another session of
the same robot (same hardware and effect, another motion and noise, later on the robot's clock,
so a slipped marker stays moved). The effect's error is what the baseline's prediction of the
effect's channels (the pot; every marker a moved link carries; all markers for a clock shift;
the slipped marker) from every other sensor of the frame (``predict --from others``) errs
beyond the oracle's, against the noise-free readings: share removed =
(E_base² − E_ext²) / (E_base² − E_oracle²), E the RMS error over the new session. Median and
worst per cause; 0.8 is the goal.

The bench reads ``/truth`` to judge; the diagnosis never sees it.

    .venv/bin/python bench/bench_diagnose_kinematics_offsim.py --logs 2 --jobs 2 --new-session
    .venv/bin/python bench/bench_diagnose_kinematics_offsim.py --quick     # a smoke run
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from experiments import kinematics_generator as gen  # noqa: E402

CAUSES = gen.CAUSES
GENERATORS = ("offsim", "project")


@dataclass(frozen=True)
class Case:
    generator: str
    cause: str | None
    channel: str | None
    size: float
    seed: int


@dataclass
class Outcome:
    case: Case
    findings: tuple  # (cause, channel, kind, held-out reduction)
    seconds: float
    truth_channel: str | None = None
    share: dict = field(default_factory=dict)
    error: str = ""
    twins: tuple = ()  # channels the top finding's data cannot tell from its own (evidence)

    @property
    def top(self) -> str:
        return f"{self.findings[0][0]}:{self.findings[0][1]}" if self.findings else ""

    @property
    def named(self) -> bool:
        """The top finding is the cause on its channel, or on a channel it says the data cannot
        tell from that one (a joint's offset along the axis of the joint before it)."""
        if not self.findings or self.findings[0][0] != self.case.cause:
            return False
        return self.findings[0][1] == self.truth_channel or self.truth_channel in self.twins

    @property
    def anywhere(self) -> bool:
        return any(f"{c}:{ch}" == f"{self.case.cause}:{self.truth_channel}" for c, ch, _, _ in self.findings)


def plan(n_logs: int, seed: int, generators, robot_dir: Path) -> list[Case]:
    """``n_logs`` logs per effect and as many clean ones, per generator; a case's channel, size
    and seed are the same for both generators."""
    layout = gen.Layout.read(robot_dir)
    rng = np.random.default_rng(seed)
    base = []
    for cause in CAUSES:
        choices = layout.channels(cause)
        for _ in range(n_logs):
            channel = choices[int(rng.integers(len(choices)))]
            base.append((cause, channel, float(rng.uniform(*gen.SIZES[cause])), int(rng.integers(2**31))))
    base += [(None, None, 0.0, int(rng.integers(2**31))) for _ in range(n_logs)]
    return [Case(g, c, ch, s, sd) for g in generators for c, ch, s, sd in base]


def session(case: Case, robot_dir: Path, duration: float) -> gen.Session:
    return gen.Session(robot_dir, duration, case.cause, case.channel, case.size or None, case.seed, case.seed)


def make_log(case: Case, robot_dir: Path, duration: float):
    if case.generator == "offsim":
        return gen.generate(session(case, robot_dir, duration))
    from diegocal.robot import load_robot
    from diegocal.sim.effects import EffectRequest
    from diegocal.sim.kinematics import KinematicsOptions, simulate_kinematics

    robot = load_robot(robot_dir)
    effects, directions = (), {}
    if case.cause is not None:
        size = case.size
        if case.cause in ("backlash", "sensor_nonlinearity"):  # the project's size is on the reading (V)
            pot = next(p for p in robot.sensors.pots if p.name == case.channel)
            size = abs(pot.gain) * case.size if case.cause == "backlash" else case.size
        if case.cause == "link_offset":  # along the link, as the offsim generator moves it
            directions = {case.channel: tuple(gen.Layout.read(robot_dir).link(case.channel))}
        effects = (EffectRequest(case.cause, case.channel, size),)
    opts = KinematicsOptions(duration=duration, effects=effects, directions=directions)
    return simulate_kinematics(robot, opts, np.random.default_rng(case.seed))


# ----------------------------------------------------------------------------- diagnosis
def diagnose_one(task) -> Outcome:
    case, robot_dir, duration, new_session = task
    from diegocal.diagnose import DiagnoseOptions, diagnose
    from diegocal.errors import DiegocalError
    from diegocal.robot import load_robot

    log = make_log(case, robot_dir, duration)
    robot = load_robot(robot_dir)
    truth = log.truth.effects[0]["channel"] if log.truth.effects else None
    start = time.process_time()
    try:
        d = diagnose(log, robot, DiagnoseOptions(domain="kinematics"))
    except DiegocalError as exc:
        return Outcome(case, (), time.process_time() - start, truth, error=str(exc))
    found = tuple((f.cause, f.channel, f.kind, float(f.gain().get("reduction", np.nan))) for f in d.findings)
    twins = tuple(d.findings[0].evidence.get("indistinguishable_from", ())) if d.findings else ()
    out = Outcome(case, found, time.process_time() - start, truth, twins=twins)
    if new_session and case.generator == "offsim" and out.named:
        out.share = new_session_share(d, log, case, robot_dir, duration)
    return out


def oracle_term(effect: dict, robot):
    """The hidden effect as the exact term of the vocabulary: its true cause, channel, dead band,
    region and start values (fitted from there)."""
    from diegocal.terms import Region, make_term

    cause, ch, v = effect["cause"], effect["channel"], effect["values"]
    if cause == "time_offset":
        return make_term(cause, ch, [v["seconds"]])
    if cause == "marker_slip":
        t0 = v["time"] + 0.5 * v["transition_s"]
        return make_term(cause, ch, list(v["dxyz"]), region=Region("time", t0, float("inf")))
    if cause == "link_offset":
        return make_term(cause, ch, list(v["dxyz"]))
    if cause == "backlash":
        gain = next(p.gain for p in robot.sensors.pots if p.name == ch)
        return make_term(cause, ch, [-0.5 * np.sign(gain) * v["width_reading"]], extra={"width": v["width_reading"]})
    return make_term(cause, ch)  # sensor_nonlinearity: its centre and range from the training readings


def effect_channels(effect: dict, robot) -> list[str]:
    """The channels an effect acts on (module docstring)."""
    cause, ch = effect["cause"], effect["channel"]
    if cause in ("backlash", "sensor_nonlinearity", "marker_slip"):
        return [ch]
    if cause == "time_offset":
        return list(robot.sensors.marker_names)
    j = robot.model.getJointId(ch)
    out = []
    for m in robot.sensors.markers:
        k = robot.model.frames[robot.frame_id(m.link)].parentJoint
        while k > 0 and k != j:
            k = robot.model.parents[k]
        if k == j:
            out.append(m.name)
    return out


def new_session_share(d, log, case: Case, robot_dir: Path, duration: float) -> dict:
    """Item 4 (module docstring): E_base, E_ext, E_oracle and the share removed."""
    from diegocal.stac.predict import OTHERS, predict

    effect = log.truth.effects[0]
    adapter, train = d.adapters[0], d.blocks.mask("train")
    robot = adapter.robot
    cals = {
        "base": adapter.calibration(adapter.fit((), train)),
        "ext": adapter.calibration(d.units[0].fitted),
        "oracle": adapter.calibration(adapter.fit((oracle_term(effect, robot),), train)),
    }
    other = gen.generate(session(case, robot_dir, duration).next())
    chans = effect_channels(effect, robot)
    sig = other.truth.signals
    err = {}
    for k, cal in cals.items():
        p = predict(other.without_truth(), robot, cal, (OTHERS,), ("pots", "markers"))
        sq = []
        for c in chans:
            if c in p.pot_names:
                e = p.pots[:, p.pot_names.index(c)] - sig["pots"].column(c)
            else:
                e = np.linalg.norm(p.markers[:, p.marker_names.index(c)] - sig["markers"].column(c), axis=-1)
            sq.append(e[np.isfinite(e)] ** 2)
        err[k] = float(np.sqrt(np.mean(np.concatenate(sq))))
    share = (err["base"] ** 2 - err["ext"] ** 2) / max(err["base"] ** 2 - err["oracle"] ** 2, 1e-30)
    return {**err, "share": float(share)}


# ----------------------------------------------------------------------------- tables
def table(outcomes) -> str:
    rows = [
        "| generator | cause | logs | named (top) | named anywhere | false alarms | what else was on top |",
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
            other: dict = {}
            for o in grp:
                if cause is None or not o.named:
                    key = o.top.split(":")[0] if o.top else ("nothing" if cause else "")
                    if key and (cause is None or o.top):
                        other[key] = other.get(key, 0) + 1
                    elif cause is not None:
                        other["nothing"] = other.get("nothing", 0) + 1
            n = len(grp)
            named = "" if cause is None else f"{sum(o.named for o in grp)}/{n}"
            anywhere = "" if cause is None else f"{sum(o.anywhere for o in grp)}/{n}"
            alarms = f"{sum(bool(o.findings) for o in grp)}/{n}" if cause is None else ""
            rows.append(
                f"| {g} | {cause or '(clean)'} | {n} | {named} | {anywhere} | {alarms} | "
                + ", ".join(f"{k} {v}" for k, v in sorted(other.items()))
                + " |"
            )
        hid = [o for o in mine if o.case.cause]
        cln = [o for o in mine if not o.case.cause]
        alarms = sum(bool(o.findings) for o in cln)
        rows.append(
            f"| **{g}** | all | {len(hid)} + {len(cln)} | **{sum(o.named for o in hid)}/{len(hid)}** | "
            f"{sum(o.anywhere for o in hid)}/{len(hid)} | **{alarms}/{len(cln)}** | |"
        )
    return "\n".join(rows)


def share_table(outcomes) -> str:
    out = [
        "| cause | logs | E_base | E_ext | E_oracle (medians) | share removed: median | worst |",
        "|---|---|---|---|---|---|---|",
    ]
    for cause in CAUSES:
        r = [o.share for o in outcomes if o.share and o.case.cause == cause]
        if not r:
            continue
        s = np.array([x["share"] for x in r])
        unit = "V" if cause in ("backlash", "sensor_nonlinearity") else "m"
        out.append(
            f"| {cause} | {len(r)} | {np.median([x['base'] for x in r]):.4g} {unit} | "
            f"{np.median([x['ext'] for x in r]):.4g} | {np.median([x['oracle'] for x in r]):.4g} | "
            f"{np.median(s):.0%} | {s.min():.0%} |"
        )
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--logs", type=int, default=2, help="logs per effect, and as many clean, per generator")
    ap.add_argument("--seed", type=int, default=31)
    ap.add_argument("--robot", choices=tuple(gen.ROBOTS), default="icub")
    ap.add_argument("--duration", type=float, default=60.0, help="log length, s")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--generator", action="append", choices=GENERATORS, help="default: both")
    ap.add_argument("--cause", action="append", choices=CAUSES, help="effects to hide (default: all; clean logs too)")
    ap.add_argument("--new-session", action="store_true", help="item 4 on every named offsim log")
    ap.add_argument("--quick", action="store_true", help="UR5, 1 log per effect, 15-s logs (a smoke run)")
    ap.add_argument("--verbose", action="store_true", help="one line per log")
    args = ap.parse_args(argv)
    if args.quick:
        args.robot, args.logs, args.duration = "ur5", 1, 15.0
    generators = tuple(args.generator or GENERATORS)
    with tempfile.TemporaryDirectory() as tmp:
        robot_dir = gen.robot_dir(Path(tmp), args.robot)
        cases = plan(args.logs, args.seed, generators, robot_dir)
        if args.cause:
            cases = [c for c in cases if c.cause in args.cause]
        print(
            f"bench_diagnose_kinematics_offsim: {args.robot}, seed {args.seed}, {args.logs} logs per effect + "
            f"{args.logs} clean per generator, {args.duration:g}-s logs, load {os.getloadavg()[0]:.1f}"
        )
        tasks = [(c, robot_dir, args.duration, args.new_session) for c in cases]
        t0 = time.perf_counter()
        if args.jobs > 1:
            with ProcessPoolExecutor(args.jobs) as pool:
                outcomes = list(pool.map(diagnose_one, tasks))
        else:
            outcomes = [diagnose_one(t) for t in tasks]
    if args.verbose:
        for o in outcomes:
            c = o.case
            extra = f" share {o.share['share']:.2f}" if o.share else ""
            extra += f" (the data cannot tell it from {', '.join(o.twins)})" if o.twins else ""
            found = [(f[0], f[1], f[2], round(f[3], 3)) for f in o.findings]
            print(
                f"{c.generator:8s} {str(c.cause):20s} {str(o.truth_channel):22s} size {c.size:<8.4g} "
                f"seed {c.seed:<11d} {found}{extra} {o.error}"
            )
    print(table(outcomes))
    if args.new_session:
        print(share_table(outcomes))
    print(
        f"{time.perf_counter() - t0:.0f} s wall, diagnosis median {np.median([o.seconds for o in outcomes]):.0f} "
        f"CPU s per log, --jobs {args.jobs}, load average at the end {os.getloadavg()[0]:.1f}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
