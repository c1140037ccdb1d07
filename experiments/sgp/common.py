"""Shared machinery of the SGP experiments (thesis §3.4): fit every method on one training log,
score it on held-out logs per test set, region and joint, and print tables.

Scores compare predictions with the *noise-free* simulated torque (``/truth`` signal ``tau``, read
here for evaluation only — the fits never see it): nMSE = mean squared error / variance of that
torque over the whole test log (thesis §3.4.2 normalises by the target's variance; using the whole
log's variance keeps regions of one log comparable). Coverage is the fraction of *measured* torques
inside mean ± 2σ (σ = ``tau_std``, measurement noise included; 0.95 expected), as ``predict``
reports it.
"""

from __future__ import annotations

import time
from collections import defaultdict
from dataclasses import dataclass, replace

import numpy as np

from diegocal.io import Log, make_stream
from diegocal.sgp import SGPOptions, fit_dynamics
from diegocal.sim.dynamics import DynamicsOptions, simulate_dynamics, true_friction
from diegocal.sim.effects import parse_effects

#: Method label -> (SGPOptions.kind, guard). "SGP" is the guarded SGP; the unguarded one is the
#: plain ML-II SGP the guard is measured against.
METHODS = {
    "PR": ("pr", False),
    "GP": ("gp", False),
    "PRGP": ("prgp", False),
    "SGP": ("sgp", True),
    "SGP-noguard": ("sgp", False),
}


@dataclass(frozen=True)
class Score:
    """One cell: a method's error on one joint of one region of one test log."""

    experiment: str
    seed: int
    method: str
    test: str
    region: str
    joint: str
    nmse: float
    coverage: float
    n: int
    fit_s: float = 0.0


SCALE_RATE = 50.0  # Hz, the scale and sizes benches' arm3 logs
CASE_NOISE = 0.01  # N·m, their torque sensor noise (white)


def friction_case(robot, n: int, seed: int, friction=None, hidden: bool = True) -> Log:
    """The scale and sizes benches' log (issue #14): arm3 at SCALE_RATE with the hidden
    cable-like friction on joint 3, sensor noise CASE_NOISE, at least ``n`` samples; ``friction``
    (:func:`same_robot`) keeps another run's robot. ``hidden=False``: the same run (trajectory,
    robot and noise: the simulator's streams are independent) without the hidden friction, where
    the rigid body with viscous and Coulomb friction, PR's model, is the true one."""
    opts = DynamicsOptions(
        duration=n / SCALE_RATE + 0.1,
        rate_hz=SCALE_RATE,
        effects=parse_effects(["position_friction:joint3"] if hidden else []),
        noise=CASE_NOISE,
        **(friction or {}),
    )
    return simulate_dynamics(robot, opts, np.random.default_rng(seed))


def select(log: Log, mask: np.ndarray) -> Log:
    """The samples of ``log`` where ``mask`` (T,) is true, truth signals included."""
    streams = {k: make_stream(s.names, s.data[mask]) for k, s in log.streams.items()}
    truth = log.truth
    if truth is not None:
        sig = {k: make_stream(s.names, s.data[mask]) for k, s in truth.signals.items()}
        truth = replace(truth, signals=sig)
    return Log(time=log.time[mask], streams=streams, robot=log.robot, rate_hz=log.rate_hz, truth=truth)


def same_robot(log: Log, robot) -> dict:
    """The true friction of a simulated training log as ``DynamicsOptions`` fields (``viscous``,
    ``coulomb`` per joint), so that a test log is of the *same* robot: the simulator draws them
    from each call's seed otherwise. Reads ``/truth`` to build test data only (fits never do)."""
    friction = true_friction(log.truth.params)
    return {k: tuple(float(friction[k][j]) for j in robot.joint_names) for k in ("viscous", "coulomb")}


def score_arrays(
    mean, std, clean, measured, names, regions: dict, experiment: str, seed: int, method: str, test: str
) -> list:
    """Scores of predictions ``mean``/``std`` (T, n) against the noise-free target ``clean`` and
    the measurement ``measured`` (T, n), for each region mask (T,) and output ``names`` (n,)."""
    var = np.var(clean, axis=0)
    inside = np.abs(measured - mean) <= 2.0 * std
    out = []
    for region, mask in regions.items():
        if not mask.any():
            continue
        err = ((mean[mask] - clean[mask]) ** 2).mean(axis=0) / var
        cov = inside[mask].mean(axis=0)
        for j, name in enumerate(names):
            out.append(
                Score(experiment, seed, method, test, region, name, float(err[j]), float(cov[j]), int(mask.sum()))
            )
    return out


def score(pred, log: Log, regions: dict, experiment: str, seed: int, method: str, test: str) -> list:
    """Scores of a :class:`~diegocal.sgp.TorquePrediction` on ``log`` for each region mask (T,):
    against the noise-free torque of ``/truth`` and the measured torque."""
    clean = log.truth.signals["tau"].data
    measured = log.streams["tau"].data
    names = log.streams["tau"].names
    return score_arrays(pred.tau, pred.tau_std, clean, measured, names, regions, experiment, seed, method, test)


def run_methods(train: Log, tests: dict, robot, base: SGPOptions, experiment: str, seed: int, methods=None) -> list:
    """Fit each method on ``train`` and score it on ``tests`` (name -> (log, {region: mask}))."""
    out = []
    for label in methods or METHODS:
        kind, guard = METHODS[label]
        start = time.perf_counter()
        model = fit_dynamics(train, robot, replace(base, kind=kind, guard=guard, seed=seed))
        fit_s = time.perf_counter() - start
        for name, (log, regions) in tests.items():
            cells = score(model.predict(log), log, regions, experiment, seed, label, name)
            out.extend(replace(c, fit_s=fit_s) for c in cells)
    return out


def aggregate(scores, field: str = "nmse", reduce=np.mean) -> dict:
    """(method, test, region, joint) -> reduced value of ``field`` over seeds."""
    groups = defaultdict(list)
    for s in scores:
        groups[(s.method, s.test, s.region, s.joint)].append(getattr(s, field))
    return {k: float(reduce(v)) for k, v in groups.items()}


def table(scores, field: str = "nmse", reduce=np.mean, title: str = "", methods=None) -> str:
    """A plain-text table: one row per (test, region, joint), one column per method; the best
    (lowest nMSE, or coverage closest to 0.95) of each row is starred."""
    agg = aggregate(scores, field, reduce)
    methods = [m for m in (methods or METHODS) if any(k[0] == m for k in agg)]
    rows = sorted({k[1:] for k in agg}, key=lambda r: [(s.test, s.region, s.joint) for s in scores].index(r))
    head = f"{'test':<12}{'region':<16}{'joint':<8}" + "".join(f"{m:>13}" for m in methods)
    lines = [title, head, "-" * len(head)] if title else [head, "-" * len(head)]
    for r in rows:
        vals = [agg.get((m,) + r, np.nan) for m in methods]
        key = np.abs(np.array(vals) - 0.95) if field == "coverage" else np.array(vals)
        best = int(np.nanargmin(key))
        cells = "".join(f"{v:>12.4g}{'*' if i == best else ' '}" for i, v in enumerate(vals))
        lines.append(f"{r[0]:<12}{r[1]:<16}{r[2]:<8}" + cells)
    return "\n".join(lines)


#: The methods SGP is judged against (thesis Fig. 3.2, 3.4, 3.9); SGP-noguard is a diagnostic.
BASELINES = ("PR", "GP", "PRGP")


@dataclass(frozen=True)
class Verdict:
    """SGP against the best baseline of one cell (test, region, joint), paired over seeds.

    ``diff`` is the seed mean of nMSE_SGP − nMSE_best and ``se`` its standard error (std/√k over
    the k seeds). ``label``: "best" when SGP's seed-mean nMSE is the lowest; "tied" when it is not
    but ``diff ≤ se`` (the seeds do not show the best baseline ahead by more than one standard
    error: the definition of "tied" fixed before measuring); "worse" otherwise.
    """

    cell: tuple
    best: str
    diff: float
    se: float
    label: str


def verdicts(scores, method: str = "SGP", baselines=BASELINES) -> list[Verdict]:
    """One :class:`Verdict` per cell where ``method`` and at least one baseline were scored."""
    by = defaultdict(dict)
    for s in scores:
        by[(s.test, s.region, s.joint)].setdefault(s.method, {})[s.seed] = s.nmse
    out = []
    for cell, per in by.items():
        if method not in per:
            continue
        rivals = [b for b in baselines if b in per]
        if not rivals:
            continue
        best = min(rivals, key=lambda b: np.mean(list(per[b].values())))
        seeds = sorted(set(per[method]) & set(per[best]))
        d = np.array([per[method][k] - per[best][k] for k in seeds])
        se = float(d.std(ddof=1) / np.sqrt(len(d))) if len(d) > 1 else float("nan")
        mean = float(d.mean())
        label = "best" if mean < 0 else ("tied" if mean <= se else "worse")
        out.append(Verdict(cell, best, mean, se, label))
    return out


def spread_table(scores, title: str = "", methods=None) -> str:
    """nMSE per cell: seed mean ± standard error per method (* lowest mean), then SGP's
    :class:`Verdict` against the best baseline (difference ± its paired standard error)."""
    methods = [m for m in (methods or METHODS) if any(s.method == m for s in scores)]
    groups = defaultdict(list)
    for s in scores:
        groups[(s.method, s.test, s.region, s.joint)].append(s.nmse)
    rows = list(dict.fromkeys((s.test, s.region, s.joint) for s in scores))
    verdict = {v.cell: v for v in verdicts(scores)}
    head = f"{'test':<11}{'region':<15}{'joint':<7}" + "".join(f"{m:>19}" for m in methods) + "  SGP vs best"
    lines = ([title] if title else []) + [head, "-" * len(head)]
    for r in rows:
        vals = [np.array(groups.get((m,) + r, [np.nan])) for m in methods]
        means = [v.mean() for v in vals]
        best = int(np.nanargmin(means))
        cells = ""
        for i, v in enumerate(vals):
            se = v.std(ddof=1) / np.sqrt(v.size) if v.size > 1 else 0.0
            cells += f"{f'{v.mean():.3g}±{se:.2g}':>18}{'*' if i == best else ' '}"
        vd = verdict.get(r)
        tail = "" if vd is None else f"  {vd.label} ({vd.best} {vd.diff:+.2g}±{vd.se:.2g})"
        lines.append(f"{r[0]:<11}{r[1]:<15}{r[2]:<7}" + cells + tail)
    return "\n".join(lines)
