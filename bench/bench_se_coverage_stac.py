"""Do STAC's ± cover the truth? (issue #31, item 5)

For ``--seeds`` logs of each generator, STAC calibrates the whole log and every estimate is
compared with the simulator's truth: the share of |estimate − truth| ≤ 2 SE, per family (pot
gains, pot biases, marker positions), pooled over the seeds. 0.90-0.98 is the goal (0.95 for
exact standard errors and an unbiased estimate). Only what the data determine is counted: pots
whose gain and bias were estimated, biases in the gauge the fit fixed
(:meth:`~diegocal.stac.model.Observation.gauge_equivalent_bias`), markers that take up no gauge.

Generators: ``offsim`` (experiments/kinematics_generator.py: minimum-jerk motion, anisotropic
white marker noise plus a slowly varying part, quantised pots) and ``project`` (``diegocal
simulate kinematics``: white noise). Both on the same robot directory (``--robot``: the blind
iCub of the generator, 32 pots and 16 markers, or the UR5). Clean logs: STAC's model is exact.

Also printed: the median |z| per family (0.67 for exact SEs) and the worst seed's share.

``--terms``: the same for the parameters of a diagnosed kinematic term, as ``diagnose`` fits it
(:class:`~diegocal.diagnose.kinematics.KinematicsAdapter`, the training blocks of a 10-block
split), on logs that hide the term's cause: a clock shift (``seconds``; both generators), a
slipped marker (``dx, dy, dz`` from its slip time; both generators: the offsim slip slides over
0.2-0.5 s and the term's time is the middle of the slide) and a pot's quadratic transfer
(``c2, c3``; the project's simulator, whose curve is the term's: c2 = its departure at the ends of
the term's range through the model's fitted gain, which takes the curve's part linear in the
reading, c3 = 0), a link offset (``dx, dy, dz``, the joint origin's shift in its parent's frame;
both generators: the project's in a random direction, the offsim's along the link; a component
the calibration takes up, e.g. along a joint axis the markers' positions absorb or across a link
whose ends' pots' biases turn it, has an infinite SE and is not counted) and a pot's dead band
(``half_width``, its dead band ``extra.width`` the true one on the reading; both generators: the
project's pot reads the link through the play, half_width = +width / 2; the offsim's reads the
motor, which leads the link, half_width = −width / 2). The term's structure (cause, channel, slip
time, dead band) is the truth's, so
the count is of the standard errors, not of the naming. A slip of a marker that takes up a leaf
gauge is placed turned about the gauge joint's axis (the fit's gauge, not the truth's frame): its
length and its component along that axis (``extra.gauge``, which the gauge leaves alone) are
counted instead, in a row of their own.

    .venv/bin/python bench/bench_se_coverage_stac.py --seeds 50 --robot icub
    .venv/bin/python bench/bench_se_coverage_stac.py --seeds 50 --robot icub --terms
    .venv/bin/python bench/bench_se_coverage_stac.py --quick
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from experiments import kinematics_generator as gen  # noqa: E402

GENERATORS = ("offsim", "project")
FAMILIES = ("gain", "bias", "marker")


def make_log(generator: str, robot_dir: Path, seed: int, duration: float):
    """A clean log of ``generator`` (module docstring)."""
    if generator == "offsim":
        return gen.generate(gen.Session(robot_dir, duration, seed=seed, hardware_seed=seed))
    from diegocal.robot import load_robot
    from diegocal.sim.kinematics import KinematicsOptions, simulate_kinematics

    robot = load_robot(robot_dir)
    return simulate_kinematics(robot, KinematicsOptions(duration=duration), np.random.default_rng(seed))


def z_scores(log, robot, cal) -> dict:
    """(estimate − truth) / SE per family, for what the data determine (module docstring)."""
    from diegocal.stac.calibration import Calibration
    from diegocal.stac.model import Observation

    truth = Calibration.from_dict(log.truth.params)
    obs = Observation(log.without_truth(), robot)
    obs.check_observable()
    order = [truth.pot_names.index(n) for n in cal.pot_names]
    tg, tb = truth.gain[order], truth.bias[order]
    b_equiv = obs.gauge_equivalent_bias(tg, tb, cal.bias)
    zg = (cal.gain - tg) / cal.gain_se
    zb = np.where(~obs.fixed_bias, (cal.bias - b_equiv) / cal.bias_se, np.nan)
    morder = [truth.marker_names.index(n) for n in cal.marker_names]
    free = obs.gauge_free_markers()
    zx = (cal.marker_xyz - truth.marker_xyz[morder]) / cal.marker_xyz_se
    zx[~free] = np.nan
    return {"gain": zg[np.isfinite(zg)], "bias": zb[np.isfinite(zb)], "marker": zx[np.isfinite(zx)].ravel()}


def run_one(task) -> dict:
    generator, robot_dir, seed, duration = task
    from diegocal.robot import load_robot
    from diegocal.stac import calibrate

    log = make_log(generator, robot_dir, seed, duration)
    robot = load_robot(robot_dir)
    start = time.process_time()
    cal = calibrate(log.without_truth(), robot).calibration
    return {"generator": generator, "seed": seed, "z": z_scores(log, robot, cal),
            "seconds": time.process_time() - start}


TERM_CASES = (("offsim", "time_offset"), ("project", "time_offset"), ("offsim", "marker_slip"),
              ("project", "marker_slip"), ("project", "sensor_nonlinearity"), ("offsim", "link_offset"),
              ("project", "link_offset"), ("offsim", "backlash"), ("project", "backlash"))


def term_one(task) -> dict:
    """One log hiding ``cause``: the term fitted with its true structure, z of its parameters."""
    generator, cause, robot_dir, seed, duration = task
    from diegocal.diagnose.kinematics import KinematicsAdapter
    from diegocal.evaluate import split_blocks
    from diegocal.robot import load_robot
    from diegocal.terms import Region, make_term

    robot = load_robot(robot_dir)
    if generator == "offsim":
        log = gen.generate(gen.Session(robot_dir, duration, cause, seed=seed, hardware_seed=seed))
    else:
        from diegocal.sim.effects import EffectRequest
        from diegocal.sim.kinematics import KinematicsOptions, simulate_kinematics

        layout = gen.Layout.read(robot_dir)
        choices = layout.channels(cause)
        channel = choices[seed % len(choices)]
        opts = KinematicsOptions(duration=duration, effects=(EffectRequest(cause, channel, None),))
        log = simulate_kinematics(robot, opts, np.random.default_rng(seed))
    effect = log.truth.effects[0]
    v, ch = effect["values"], effect["channel"]
    region = None
    if cause == "marker_slip":
        t0 = v["time"] + 0.5 * v.get("transition_s", 0.0)
        region = Region("time", float(log.time[np.searchsorted(log.time, t0)]), float("inf"))
    extra = {"width": v["width_reading"]} if cause == "backlash" else None
    adapter = KinematicsAdapter(log, robot)
    train = split_blocks(log.n_samples, 10).mask("train")
    start = time.process_time()
    fitted = adapter.fit((make_term(cause, ch, region=region, extra=extra),), train)
    term = fitted.terms[0]
    if cause == "time_offset":
        truth = [v["seconds"]]
    elif cause in ("marker_slip", "link_offset"):  # a link offset's part the calibration takes up: SE inf
        truth = v["dxyz"]
    elif cause == "backlash":  # offsim's pot reads the motor, which leads the link: the reading leads
        truth = [0.5 * v["width_reading"] * (-1.0 if generator == "offsim" else 1.0)]
    else:  # the model's gain: the curve's part linear in the reading is the gain's, not the term's
        g = fitted.cal.gain[fitted.cal.pot_names.index(ch)]
        truth = [v["c2"] * (term.extra["half"] / g) ** 2, 0.0]
    z = np.where(np.isfinite(term.stderrs), (term.values - np.asarray(truth, float)) / term.stderrs, np.nan)
    gauge = term.extra.get("gauge")
    if gauge:  # its components in the gauge the fit fixed: what the gauge leaves alone instead
        d, a = np.asarray(truth, float), np.asarray(gauge["axis"], float)
        got = [(gauge[k]["value"], gauge[k]["stderr"]) for k in ("length", "along_axis")]
        z = np.array([(v - t) / e for (v, e), t in zip(got, (np.linalg.norm(d), a @ d), strict=True)])
        cause += " (gauge: length, along axis)"
    return {"generator": generator, "cause": cause, "seed": seed, "z": z, "seconds": time.process_time() - start}


def term_table(rows) -> str:
    out = ["| generator | term | logs | parameters | within 2 SE | median abs z (0.67) |", "|---|---|---|---|---|---|"]
    cases = [(g, c) for g, cause in TERM_CASES for c in (cause, cause + " (gauge: length, along axis)")]
    for g, cause in cases:
        mine = [r for r in rows if r["generator"] == g and r["cause"] == cause]
        if mine:
            z = np.concatenate([r["z"] for r in mine])
            z = z[np.isfinite(z)]
            out.append(f"| {g} | {cause} | {len(mine)} | {z.size} | {np.mean(np.abs(z) <= 2):.3f} | "
                       f"{np.median(np.abs(z)):.2f} |")
    return "\n".join(out)


def table(rows) -> str:
    out = ["| generator | family | seeds | estimates | within 2 SE | median abs z (0.67) | worst seed |",
           "|---|---|---|---|---|---|---|"]
    for g in GENERATORS:
        mine = [r for r in rows if r["generator"] == g]
        if not mine:
            continue
        for fam in FAMILIES:
            z = np.concatenate([r["z"][fam] for r in mine])
            if not z.size:
                continue
            per = [np.mean(np.abs(r["z"][fam]) <= 2) for r in mine if r["z"][fam].size]
            out.append(f"| {g} | {fam} | {len(mine)} | {z.size} | {np.mean(np.abs(z) <= 2):.3f} | "
                       f"{np.median(np.abs(z)):.2f} | {min(per):.2f} |")
    return "\n".join(out)


def _map(fn, tasks, jobs: int) -> list:
    if jobs > 1:
        with ProcessPoolExecutor(jobs) as pool:
            return list(pool.map(fn, tasks))
    return [fn(t) for t in tasks]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=50)
    ap.add_argument("--seed", type=int, default=0, help="first seed")
    ap.add_argument("--robot", choices=tuple(gen.ROBOTS), default="icub")
    ap.add_argument("--duration", type=float, default=30.0, help="log length, s")
    ap.add_argument("--generator", action="append", choices=GENERATORS, help="default: both")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--terms", action="store_true", help="the diagnosed terms' parameters (module docstring)")
    ap.add_argument("--cause", action="append", help="with --terms: only these causes (default: every one)")
    ap.add_argument("--quick", action="store_true", help="3 seeds of 10-s UR5 logs (a smoke run)")
    args = ap.parse_args(argv)
    if args.quick:
        args.seeds, args.robot, args.duration = 3, "ur5", 10.0
    generators = tuple(args.generator or GENERATORS)
    with tempfile.TemporaryDirectory() as tmp:
        robot_dir = gen.robot_dir(Path(tmp), args.robot)
        last = args.seed + args.seeds - 1
        print(f"bench_se_coverage_stac: {args.robot}, {args.duration:g}-s logs, seeds {args.seed}..{last}, "
              f"load {os.getloadavg()[0]:.1f}")
        t0 = time.perf_counter()
        if args.terms:
            tasks = [(g, c, robot_dir, args.seed + i, args.duration) for g, c in TERM_CASES
                     if g in generators and c in (args.cause or (c,)) for i in range(args.seeds)]
            rows = _map(term_one, tasks, args.jobs)
            print(term_table(rows))
        else:
            tasks = [(g, robot_dir, args.seed + i, args.duration) for g in generators for i in range(args.seeds)]
            rows = _map(run_one, tasks, args.jobs)
            print(table(rows))
    print(f"{time.perf_counter() - t0:.0f} s wall, fit median {np.median([r['seconds'] for r in rows]):.1f} CPU s "
          f"per log, load average at the end {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
