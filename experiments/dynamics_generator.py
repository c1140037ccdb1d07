"""An independent torque-log generator, to judge ``diagnose`` on data it was not built around.

Written apart from :mod:`diegocal.sim.dynamics` (it imports nothing of diegocal's simulators):
any URDF (the robots of ``example-robot-data``: UR5, Panda, with their real inertias), a Fourier
excitation inside the joint limits with exact q, qd, qdd, and

.. math::  \\tau = \\mathrm{RNEA}(q, \\dot q, \\ddot q) + \\eta_v \\dot q + f_c(\\dot q) + \\tau_{hidden} + \\varepsilon

with the Coulomb friction f_c either ``fc·sign(qd)`` (the model's own shape) or, as real geared
joints have it, switching smoothly through zero velocity (``fc·tanh(qd/v_s)``), and ε white noise
of a given fraction of each joint's torque spread. ``hidden`` effects, one per log:

- in the vocabulary: ``position_friction`` (Coulomb + viscous inside a window of the joint's
  range), ``payload`` (a point mass on a link: RNEA of a heavier link), ``spring`` (about the
  joint's mid-range), ``torque_offset``, ``torque_gain`` (the joint's sensor reads its torque,
  friction included, times 1 + the effect's scale), ``transmission_backlash`` (play between the
  joint's motor, whose angle is logged, and its link: RNEA at the link's angle, which stays put
  until the motor has crossed the gap; the scale is the half-width, rad, at most 0.1);
- outside it, shapes a real robot has that no term of the vocabulary names: ``stribeck`` (static
  friction above Coulomb decaying with speed), ``cogging`` (a torque periodic in the joint angle),
  ``drifting_friction`` (Coulomb friction that grows over the session, as a gearbox warms),
  ``load_friction`` (friction in proportion to the joint's load torque), ``hose`` (a torque on one
  joint from another joint's angle: a cable or hose pulled by the next link), ``drifting_offset``
  (the torque sensor's zero drifting linearly over the session, as its electronics warm).

A second *session* of the same robot is the same ``robot_seed``, duration and rate with another
``seed`` (trajectory and noise): the robot's friction, noise level and hidden effect (its joint,
size and parameters) are drawn against the torque spread and joint ranges of a reference
trajectory that ``robot_seed`` alone draws (the session's own when ``seed == robot_seed``), so
that they do not change with the session's motion. Logs carry ``/truth``: the effect, its
parameters, and the noise-free torque with and without the hidden effect, for judging only.
"""

from __future__ import annotations

import sysconfig
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin

from diegocal.io import Log, Truth, make_stream

SHARE = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix" / "share" / "example-robot-data" / "robots"
URDFS = {
    "ur5": "ur_description/urdf/ur5_joint_limited_robot.urdf",
    "panda": "panda_description/urdf/panda.urdf",
}
IN_VOCABULARY = ("position_friction", "payload", "spring", "torque_offset", "torque_gain", "transmission_backlash")
#: the largest half-width a transmission_backlash is sized to, rad (the registry's bound)
MAX_HALF_WIDTH = 0.1
OUT_OF_VOCABULARY = ("stribeck", "cogging", "drifting_friction", "load_friction", "hose", "drifting_offset")


def urdf(name: str) -> Path:
    """The URDF of an example-robot-data robot (``ur5``, ``panda``) or a path as given."""
    return SHARE / URDFS[name] if name in URDFS else Path(name)


@dataclass(frozen=True)
class Session:
    """One log: robot (name or URDF), duration (s), rate (Hz), ``hidden`` effect (or None),
    ``size`` of the hidden effect in multiples of the joint's noise (RMS over the log), the noise
    as a fraction of each joint's torque spread, Coulomb ``smooth_scale`` (rad/s; 0: sign(qd)),
    ``seed`` (trajectory, noise) and ``robot_seed`` (friction, the effect's joint and parameters);
    ``coulomb``: the range the Coulomb level is drawn from, a fraction of the joint's torque spread."""

    robot: str = "ur5"
    duration: float = 60.0
    rate_hz: float = 100.0
    hidden: str | None = None
    size: float = 6.0
    noise: float = 0.015
    smooth_scale: float = 0.02
    seed: int = 0
    robot_seed: int = 0
    joint: int | None = None  # the hidden effect's joint (index); None: drawn from robot_seed
    coulomb: tuple = (0.05, 0.15)
    extra: dict = field(default_factory=dict)


def excitation(model, time: np.ndarray, rng: np.random.Generator, harmonics: int = 5, f0: float = 0.1):
    """Fourier series per joint (base frequency f0 Hz, ``harmonics`` terms) about the middle of the
    joint's range, scaled to 80 % of the half-range (at most ±2 rad): q, qd, qdd (T, n)."""
    n = model.nq
    lo, hi = np.maximum(model.lowerPositionLimit, -2.5), np.minimum(model.upperPositionLimit, 2.5)
    centre, half = 0.5 * (lo + hi), np.minimum(0.5 * (hi - lo), 2.0)
    w = 2 * np.pi * f0 * np.arange(1, harmonics + 1)
    a = rng.normal(size=(harmonics, n)) / np.arange(1, harmonics + 1)[:, None]
    b = rng.normal(size=(harmonics, n)) / np.arange(1, harmonics + 1)[:, None]
    s, c = np.sin(np.outer(time, w)), np.cos(np.outer(time, w))
    x = s @ a + c @ b
    xd = (c * w) @ a - (s * w) @ b
    xdd = -(s * w**2) @ a - (c * w**2) @ b
    k = 0.8 * half / np.abs(x).max(axis=0)
    return centre + k * x, k * xd, k * xdd


def rnea(model, q, qd, qdd) -> np.ndarray:
    data = model.createData()
    return np.array([pin.rnea(model, data, a, b, c) for a, b, c in zip(q, qd, qdd, strict=True)])


def link_angle(motor: np.ndarray, half_width: float) -> np.ndarray:
    """The link's angle (T,) behind a motor's (T,) through a gear's play of ``half_width`` rad:
    it starts on the motor's first angle and moves only when the motor pushes it, half-width off."""
    link = np.array(motor, float, copy=True)
    for k in range(1, link.size):
        link[k] = np.clip(link[k - 1], motor[k] - half_width, motor[k] + half_width)
    return link


def _heavier(model, joint: int, mass: float, lever: np.ndarray):
    """A copy of ``model`` whose body of ``joint`` carries a point mass at ``lever`` (its frame)."""
    out = model.copy()
    out.inertias[joint + 1] = out.inertias[joint + 1] + pin.Inertia(mass, lever, np.zeros((3, 3)))
    return out


def hidden_torque(
    name: str, model, q, qd, qdd, time, j: int, rng, base_tau, applied, ref=None, ref_qd=None
) -> tuple[np.ndarray, dict]:
    """The hidden effect's torque (T, n) before sizing, and its parameters (shape only);
    ``base_tau`` the rigid body's torque, ``applied`` with friction; ``ref``, ``ref_qd`` the
    reference trajectory's q and qd (T', n), whose ranges and spread place and shape the effect
    (default: this session's)."""
    T, n = q.shape
    out = np.zeros((T, n))
    ref = q if ref is None else ref
    ref_qd = qd if ref_qd is None else ref_qd
    lo, hi = ref[:, j].min(), ref[:, j].max()
    if name == "position_friction":
        start = lo + rng.uniform(0.55, 0.75) * (hi - lo)
        inside = q[:, j] >= start
        out[:, j] = inside * (np.sign(qd[:, j]) + 0.5 * qd[:, j] / np.std(ref_qd[:, j]))
        return out, {"low": float(start), "high": float(hi)}
    if name == "payload":
        lever = rng.uniform(-0.1, 0.1, 3)
        out = rnea(_heavier(model, j, 1.0, lever), q, qd, qdd) - base_tau
        return out, {"link_joint": j, "lever": lever.tolist()}
    if name == "spring":
        out[:, j] = q[:, j] - 0.5 * (lo + hi)
        return out, {"rest": float(0.5 * (lo + hi))}
    if name == "torque_offset":
        out[:, j] = 1.0
        return out, {}
    if name == "torque_gain":  # sized: the scale is the gain error
        out[:, j] = applied[:, j]
        return out, {}
    if name == "transmission_backlash":  # per rad of a small play; generate() makes it exact at its size
        moved = q.copy()
        moved[:, j] = link_angle(q[:, j], 0.01)
        return (rnea(model, moved, qd, qdd) - base_tau) / 0.01, {}
    if name == "stribeck":
        vs = rng.uniform(0.03, 0.1)
        out[:, j] = np.sign(qd[:, j]) * np.exp(-((qd[:, j] / vs) ** 2))
        return out, {"velocity_scale": float(vs)}
    if name == "cogging":
        period = rng.uniform(0.2, 0.5)
        out[:, j] = np.sin(2 * np.pi * q[:, j] / period + rng.uniform(0, 2 * np.pi))
        return out, {"period": float(period)}
    if name == "drifting_friction":
        out[:, j] = (time - time[0]) / (time[-1] - time[0]) * np.tanh(qd[:, j] / 0.02)
        return out, {"shape": "grows linearly over the session"}
    if name == "drifting_offset":
        out[:, j] = (time - time[0]) / (time[-1] - time[0])
        return out, {"shape": "grows linearly over the session from 0"}
    if name == "load_friction":
        out[:, j] = np.abs(base_tau[:, j]) * np.tanh(qd[:, j] / 0.02)
        return out, {"shape": "|load| tanh(qd/0.02)"}
    if name == "hose":
        i = (j + 1) % n
        out[:, j] = q[:, i] - ref[:, i].mean()
        return out, {"from_joint": i}
    raise ValueError(f"unknown hidden effect {name!r}; known: {IN_VOCABULARY + OUT_OF_VOCABULARY}")


def generate(session: Session) -> Log:
    """A torque log of ``session`` (module docstring) with its truth."""
    path = urdf(session.robot)
    model = pin.buildModelFromUrdf(str(path))
    names = [model.names[i] for i in range(1, model.njoints)]
    robot_rng = np.random.default_rng(session.robot_seed)
    traj_rng, noise_rng = np.random.default_rng(session.seed).spawn(2)
    time = np.arange(0.0, session.duration, 1.0 / session.rate_hz)
    q, qd, qdd = excitation(model, time, traj_rng)
    base = rnea(model, q, qd, qdd)
    if session.seed == session.robot_seed:
        ref_q, ref_qd, ref_base = q, qd, base
    else:  # the robot's reference trajectory: what its friction, noise and effect are drawn against
        ref_q, ref_qd, ref_qdd = excitation(model, time, np.random.default_rng(session.robot_seed).spawn(2)[0])
        ref_base = rnea(model, ref_q, ref_qd, ref_qdd)
    spread = ref_base.std(axis=0)
    fc = robot_rng.uniform(*session.coulomb) * spread
    fv = robot_rng.uniform(0.02, 0.05) * spread / np.maximum(ref_qd.std(axis=0), 1e-9)
    def coulomb(v):
        return np.tanh(v / session.smooth_scale) if session.smooth_scale > 0 else np.sign(v)

    friction = fv * qd + fc * coulomb(qd)
    clean = base + friction
    noise = session.noise * spread
    effect = {}
    hidden = np.zeros_like(clean)
    if session.hidden:
        j = session.joint if session.joint is not None else int(robot_rng.integers(1, model.nq))
        fork = np.random.Generator(np.random.PCG64())  # the same draws of the shape's parameters
        fork.bit_generator.state = robot_rng.bit_generator.state
        shape, params = hidden_torque(
            session.hidden, model, q, qd, qdd, time, j, robot_rng, base, clean, ref_q, ref_qd
        )
        if session.seed == session.robot_seed:
            rms = np.sqrt(np.mean(shape[:, j] ** 2))
        else:  # sized on the reference trajectory, as the robot is
            ref_clean = ref_base + fv * ref_qd + fc * coulomb(ref_qd)
            ref_shape, _ = hidden_torque(
                session.hidden, model, ref_q, ref_qd, ref_qdd, time, j, fork, ref_base, ref_clean, ref_q, ref_qd
            )
            rms = np.sqrt(np.mean(ref_shape[:, j] ** 2))
        scale = session.size * noise[j] / rms
        hidden = scale * shape
        if session.hidden == "transmission_backlash":  # the scale is the half-width: the link's RNEA
            scale = min(scale, MAX_HALF_WIDTH)
            moved = q.copy()
            moved[:, j] = link_angle(q[:, j], scale)
            hidden = rnea(model, moved, qd, qdd) - base
        effect = {"cause": session.hidden, "channel": names[j], "scale": float(scale), **params}
    measured = clean + hidden + noise * noise_rng.standard_normal(clean.shape)
    streams = {k: make_stream(names, v) for k, v in (("q", q), ("qd", qd), ("qdd", qdd), ("tau", measured))}
    truth = Truth(
        params={"viscous": dict(zip(names, fv.tolist(), strict=True)), "coulomb": dict(zip(names, fc.tolist(),
                strict=True)), "noise": dict(zip(names, noise.tolist(), strict=True)),
                "smooth_scale": session.smooth_scale},
        effects=[effect] if effect else [],
        signals={"tau": make_stream(names, clean + hidden), "tau_hidden": make_stream(names, hidden)},
    )
    return Log(time=time, streams=streams, robot=str(path), rate_hz=session.rate_hz, truth=truth)
