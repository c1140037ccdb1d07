"""Does `diagnose` say `unexplained` rather than a wrong name when the cause is outside its
vocabulary, name what is inside it on a robot it was not built around, and does the extended
model generalise to another session? (issue #31, items 1, 2 and 4)

Logs come from :mod:`experiments.dynamics_generator` (an independent generator: a UR5 of
example-robot-data with its real inertias, a Fourier excitation, white noise of 1.5 % of each
joint's torque spread) and hide one effect (6 × the joint's noise, RMS); the friction switches
smoothly through zero velocity, except on the in-vocabulary logs (the model's sign(qd), so that
the baseline's error is the hidden effect's):

- out of the vocabulary (``stribeck``, ``cogging``, ``drifting_friction``, ``load_friction``,
  ``hose``) and the smooth friction alone (``smooth``: nothing else hidden): a log is *misnamed*
  when any finding names a cause that is not an acceptable name for its shape (:data:`ACCEPTABLE`:
  a friction shape may be named as the friction near zero velocity; anything may be
  ``unexplained``) or for the smooth friction every joint of these logs has (the friction near
  zero velocity, on any joint); *unexplained* counts the logs called ``unexplained`` on the
  hidden effect's joint;
- in the vocabulary (``position_friction``, ``payload``, ``spring``, ``torque_offset``): *named*
  when the top finding is the cause on its joint (a payload on its link: any joint's
  ``payload``), and the extended model is predicted on another session of the same robot (another
  trajectory and noise): the share of what the effect costs the baseline on that joint, against
  the noise-free truth, that it removes (:func:`new_session_share`), median and worst.

Payload logs are diagnosed with ``--inertia nominal`` (an identified rigid body fits a payload).
The bench reads ``/truth`` to judge only.

    python bench/bench_diagnose_oov.py                   # 10 logs per shape
    python bench/bench_diagnose_oov.py --logs 3 --seed 1
    python bench/bench_diagnose_oov.py --robot panda --logs 4
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from diegocal.diagnose import DiagnoseOptions, diagnose  # noqa: E402
from diegocal.robot.resolve import robot_for_log  # noqa: E402
from experiments.dynamics_generator import IN_VOCABULARY, OUT_OF_VOCABULARY, Session, generate  # noqa: E402

#: Causes that may name each out-of-vocabulary shape without being wrong (besides ``unexplained``).
FRICTION_SHAPE = {"stribeck_friction"}
ACCEPTABLE = {
    "smooth": FRICTION_SHAPE,
    "stribeck": FRICTION_SHAPE,
    "cogging": set(),
    "drifting_friction": set(),
    "load_friction": {"load_friction"},
    "hose": set(),
    "drifting_offset": set(),
}


def run_one(shape: str, seed: int, robot: str = "ur5", duration: float = 60.0) -> dict:
    """Diagnose one log; judge it; for an in-vocabulary effect, the new session's share removed."""
    hidden = None if shape == "smooth" else shape
    smooth = 0.0 if shape in IN_VOCABULARY else 0.02  # the effect alone, or on smooth friction
    session = Session(robot=robot, duration=duration, hidden=hidden, seed=seed, robot_seed=seed, smooth_scale=smooth)
    log = generate(session)
    rob = robot_for_log(None, log)
    options = DiagnoseOptions(domain="dynamics", inertia="nominal" if shape == "payload" else "identified")
    start = time.process_time()
    d = diagnose(log, rob, options)
    seconds = time.process_time() - start
    effect = log.truth.effects[0] if log.truth.effects else {}
    names = [(f.cause, f.channel) for f in d.findings]
    out = {"shape": shape, "seed": seed, "findings": names, "seconds": seconds, "channel": effect.get("channel")}
    if shape in IN_VOCABULARY:
        top = names[0] if names else None
        out["named"] = bool(top) and top[0] == shape and (shape == "payload" or top[1] == effect["channel"])
        out["removed"] = new_session_share(d, session, effect) if out["named"] else float("nan")
    else:
        # every joint's friction switches smoothly (smooth_scale): its shape is a right name anywhere
        ok = ACCEPTABLE[shape] | FRICTION_SHAPE | {"unexplained"}
        out["misnamed"] = any(c not in ok for c, _ in names)
        hidden_on = effect.get("channel")
        out["unexplained"] = any(c == "unexplained" and (hidden_on is None or j == hidden_on) for c, j in names)
    return out


def oracle_terms(effect: dict, robot) -> tuple:
    """The hidden effect as the exact term(s) of the vocabulary (its true shape, region and rest
    angle; values fitted): what an extended model could at best be."""
    from diegocal.sgp.bodies import payload_links
    from diegocal.terms import Region, make_term

    cause, joint = effect["cause"], effect["channel"]
    if cause == "torque_offset":
        return (make_term(cause, joint),)
    if cause == "spring":
        return (make_term(cause, joint, extra={"reference": effect["rest"]}),)
    if cause == "position_friction":
        upper = float(robot.upper[robot.joint_index(joint)])
        return (make_term(cause, joint, region=Region(f"q.{joint}", effect["low"], upper)),)
    if cause == "payload":
        return (make_term(cause, payload_links(robot)[robot.joint_index(joint)]),)
    if cause == "torque_gain":  # a filter: held at its true value
        return (make_term(cause, joint, {"gain_error": effect["scale"]}),)
    if cause == "transmission_backlash":  # a filter of the angles: held at its true half-width
        return (make_term(cause, joint, {"half_width": effect["scale"]}),)
    raise ValueError(cause)


def new_session_share(d, session: Session, effect: dict) -> float:
    """On another session of the same robot, on the effect's joint: the share of what the effect
    costs the baseline that the extended model removes, against the noise-free truth:
    (baseline − extended) / (baseline − oracle) in RMS error, the oracle the baseline with the
    effect's exact term (:func:`oracle_terms`) fitted on the same training blocks. Both models also
    err on states the first session did not visit (the rigid body's parameters), which no term can
    remove; the oracle measures that floor."""
    from diegocal.sgp.model import DynamicsModel

    other = generate(replace(session, seed=session.seed + 10_000))
    adapter, train = d.adapters[0], d.blocks.mask("train")
    model = d.units[0].fitted.model
    base = adapter.fit((), train).model
    rows = train & np.isfinite(adapter.tau).all(axis=1)
    oracle = DynamicsModel(adapter.robot, adapter._options(), adapter.joints, oracle_terms(effect, adapter.robot))
    oracle.fit_arrays(adapter.q[rows], adapter.qd[rows], adapter.qdd[rows], adapter.tau[rows], time=adapter.time[rows])
    names = model.robot.joint_names
    q, qd, qdd = (other.stream(s).select(names).data for s in ("q", "qd", "qdd"))
    k = list(model.joint_names).index(effect["channel"])
    truth = other.truth.signals["tau"].select(model.joint_names).data[:, k]
    err = [
        np.sqrt(np.mean((m.predict_arrays(q, qd, qdd, other.time, variance=False).tau[:, k] - truth) ** 2))
        for m in (base, model, oracle)
    ]
    return float((err[0] - err[1]) / (err[0] - err[2])) if err[0] > err[2] else float("nan")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--logs", type=int, default=10, help="Logs per shape.")
    parser.add_argument("--seed", type=int, default=0, help="First seed (each log its own).")
    parser.add_argument("--shape", action="append", help="Shapes to run (repeatable); default all.")
    parser.add_argument("--duration", type=float, default=60.0, help="Log length, s.")
    parser.add_argument("--robot", default="ur5", help="example-robot-data robot (ur5, panda) or a URDF path.")
    parser.add_argument("--verbose", action="store_true", help="One line per log.")
    args = parser.parse_args(argv)
    shapes = args.shape or ["smooth", *OUT_OF_VOCABULARY, *IN_VOCABULARY]
    load = os.getloadavg()[0]
    print(f"bench_diagnose_oov: {args.robot}, {args.duration:g} s logs, seeds {args.seed}.., load {load:.1f}")
    print("| shape | logs | misnamed | unexplained | named | new session: share removed (median / worst) | CPU s |")
    print("|---|---|---|---|---|---|---|")
    for shape in shapes:
        rows = [run_one(shape, args.seed + i, args.robot, args.duration) for i in range(args.logs)]
        if args.verbose:
            for r in rows:
                print(f"    {shape} seed {r['seed']}: {r['findings']} (hidden on {r['channel']})")
        cpu = np.median([r["seconds"] for r in rows])
        if shape in IN_VOCABULARY:
            named = sum(r["named"] for r in rows)
            x = np.array([r["removed"] for r in rows if np.isfinite(r["removed"])])
            share = f"{np.median(x):.0%} / {x.min():.0%}" if x.size else "–"
            print(f"| {shape} | {len(rows)} | | | {named}/{len(rows)} | {share} | {cpu:.1f} |")
        else:
            mis = sum(r["misnamed"] for r in rows)
            unex = sum(r["unexplained"] for r in rows)
            print(f"| {shape} | {len(rows)} | {mis}/{len(rows)} | {unex}/{len(rows)} | | | {cpu:.1f} |")
    print(f"load average at the end: {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
