"""Dynamics simulator: joint torques of any robot directory, with friction and injected effects.

The measured torque of a prescribed trajectory is the inverse dynamics of thesis eq. (3.29),

.. math::  \\tau = M(q)\\ddot q + C(q, \\dot q)\\dot q + \\tau^g(q) + \\eta_v \\dot q
           + \\eta_c\\,\\mathrm{sign}(\\dot q) + \\tau^{\\text{eff}}(q, \\dot q)
           + \\tau^{\\text{offset}} + \\varepsilon,

(the thesis writes eq. 3.29 with the opposite sign convention for M, C and τ^g; we use Pinocchio's
``rnea``, i.e. the torque the actuators apply), with ε ~ N(0, noise²) i.i.d. per sample and joint.
Integrated trajectories (the reaction wheel's ``pole-down`` / ``pole-up``, thesis §3.4.2) drive the
same true dynamics forward (``aba`` on τ minus friction and effects, RK4) and record the applied
torque: the motor torque on actuated joints and the random disturbance torque on the passive pole
(the thesis predicts accelerations, a forward model; diegocal's SGP predicts torques, so the pole's
"torque" is the disturbance that the process noise of the thesis stands for).

Effects (DESIGN.md vocabulary, domain ``dynamics``) are named with ``--effect NAME[:CHANNEL][=SIZE]``;
their true values go to ``/truth`` effects as ``{cause, channel, region, values}``; the true
friction and inertial parameters to ``/truth`` params. Nothing here reads ``/truth`` back. Each is
a physical shape of its own (never a candidate term of ``diagnose``):

- ``coulomb_friction``, ``viscous_friction``, ``position_friction`` (Coulomb + viscous while q_j
  is in the region), ``spring`` (about the neutral angle), ``torque_offset`` (sensor bias);
- ``armature``: a rotor inertia on the joint (Pinocchio's ``model.armature``, in rnea and aba);
- ``coupled_friction``: a motor turning with v = qd_j + qd_{j-1} (the TX40's wrist, joint j and
  the one before it; the one after for the first joint): a smooth Coulomb c·tanh(v / 0.05) plus
  viscous η v on joint j, the same on its partner (ratio 1);
- ``stribeck_friction``: static friction above the Coulomb level, a·sign(qd_j)·exp(−|qd_j| / vs)
  (amplitude a, velocity_scale vs = 0.05 rad/s);
- ``load_friction``: a gear's friction that grows with the torque it transmits,
  c·|τ_rb,j|·sign(qd_j), τ_rb the torque the true rigid body applies (``rnea`` at the links'
  angles with any payload, less the armature's). Prescribed trajectories only;
- ``torque_lag``: joint j's torque sensor is a first-order low-pass filter (time constant lag);
- ``torque_gain``: joint j's torque sensor reads (1 + gain_error) x the torque (a miscalibrated
  sensor, a motor's torque constant off where torque is read from current);
- ``transmission_backlash``: play of half-width b between joint j's motor (q, the encoder's) and
  its link, which lags it by up to b: ``rnea`` at the links' angles, the motor's velocity and
  acceleration; friction stays the motor's. Prescribed trajectories only;
- ``payload``: a point mass on a link (default the last);
- ``link_inertia``: the URDF's inertial parameters of a link's body too large by a fraction (the
  truth is (1 − fraction) times them: no body added to the link makes the difference).

SIZE is the effect's magnitude: a torque in N·m (Coulomb level, RMS viscous torque on the reference
excitation, the spring's torque at half the range, the offset, RMS armature torque, the Stribeck
amplitude), the time constant in s for ``torque_lag``, the relative gain error for ``torque_gain``,
the coefficient (dimensionless) for ``load_friction``, the half-width in rad for
``transmission_backlash`` (at most the registry's MAX_BACKLASH_RAD), the mass in kg for
``payload``, the fraction (under 1) for ``link_inertia``. Without it: scaled to the robot (a
backlash: 0.02 rad; a load friction: 0.05).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
import pinocchio as pin

from diegocal.causes import MAX_BACKLASH_RAD
from diegocal.errors import NumericalError, RobotConfigError
from diegocal.io import Log, Truth, make_stream
from diegocal.io.bundle import LAYOUT
from diegocal.sgp.regressor import INERTIAL_NAMES
from diegocal.sim.dynamics_truth import true_friction, true_inertial  # noqa: F401  (importable from here)
from diegocal.sim.effects import SimOptionError, check_channel, check_effects, effect_record
from diegocal.sim.trajectories import (
    excitation,
    figure_eight,
    lqr_gain,
    ou_noise,
    rollout,
    sum_of_sines,
    time_base,
    whirl,
)
from diegocal.sim.true_dynamics import COUPLED_SMOOTHING, EffectTerm, TrueDynamics
from diegocal.terms import make_term

TRAJECTORIES = (
    "excitation",
    "whirl",
    "figure8-horizontal",
    "figure8-vertical",
    "pole-down",
    "pole-up",
)
#: Joint effects act on one joint's torque; ``payload`` and ``link_inertia`` on a link's inertia.
JOINT_EFFECTS = (
    "coulomb_friction",
    "viscous_friction",
    "position_friction",
    "spring",
    "torque_offset",
    "armature",
    "coupled_friction",
    "torque_lag",
    "torque_gain",
    "transmission_backlash",
    "stribeck_friction",
    "load_friction",
)
#: the Stribeck peak's default velocity scale, rad/s
STRIBECK_SCALE = 0.05


@dataclass(frozen=True)
class DynamicsOptions:
    """What to simulate. Torques in N·m, friction in N·m·s/rad and N·m, regions in rad.

    ``viscous``/``coulomb``: one value for every joint, a per-joint sequence, or None for a
    default scaled to the robot (10 % / 5 % of each joint's RMS rigid-body torque on a reference
    excitation, times U(0.8, 1.2)). ``regions``: joint -> (low, high) where ``position_friction``
    acts (default: thesis §3.1.1's [2, 2.5] rad on continuous-range joints, else the top 20 % of
    the range, "near the limit" as in §3.4.4). ``drive``/``disturbance``: peak motor torque and
    disturbance std for the integrated trajectories (None: scaled to the robot).
    ``figure8_size``: the figure-eight's half-width and half-height as fractions of the chain
    length from the first joint to the last link (arm3: 1.0 m); ``figure8_period`` s.
    ``robot_seed``: the seed whose robot this session records (its friction and its effects'
    channels, sizes and regions, drawn as a session of that seed draws them), so that logs of
    several seeds can be of one robot; None: this session's own seed (a robot of its own).
    """

    duration: float = 20.0
    rate_hz: float = 100.0
    trajectory: str = "excitation"
    effects: tuple = ()
    noise: float = 0.01
    viscous: float | tuple | None = None
    coulomb: float | tuple | None = None
    regions: dict = field(default_factory=dict)
    effect_scale: float = 1.0
    drive: float | None = None
    disturbance: float | None = None
    figure8_size: tuple = (0.12, 0.06)  # fractions of the arm's reach
    figure8_period: float = 4.0
    robot_seed: int | None = None


def robot_scales(robot) -> tuple[np.ndarray, np.ndarray]:
    """Per-joint RMS rigid-body torque (N·m) and RMS velocity (rad/s) on a fixed reference
    excitation (20 s at 50 Hz, generator seeded 0: a property of the robot, not of the run)."""
    ref = excitation(robot.lower, robot.upper, time_base(20.0, 50.0), np.random.default_rng(0))
    data = robot.model.createData()
    tau = np.array([pin.rnea(robot.model, data, q, v, a) for q, v, a in zip(ref.q, ref.qd, ref.qdd, strict=True)])
    s = np.maximum(np.sqrt((tau**2).mean(0)), 1e-3)
    return s, np.maximum(np.sqrt((ref.qd**2).mean(0)), 1e-3)


def _per_joint(value, default: np.ndarray, n: int, what: str) -> np.ndarray:
    if value is None:
        return default
    arr = np.broadcast_to(np.asarray(value, dtype=float), (n,)) if np.ndim(value) == 0 else np.asarray(value, float)
    if arr.shape != (n,) or not np.isfinite(arr).all() or (arr < 0).any():
        raise SimOptionError(f"{what}: expected one non-negative value or {n} (one per joint), got {value!r}")
    return arr.copy()


def default_region(robot, j: int) -> tuple[float, float]:
    """Default ``position_friction`` region of joint ``j`` (rad); see :class:`DynamicsOptions`."""
    lo, hi = robot.lower[j], robot.upper[j]
    if hi - lo >= 2 * np.pi - 1e-6:
        return 2.0, 2.5
    return float(hi - 0.2 * (hi - lo)), float(hi)


def build_true_dynamics(robot, options: DynamicsOptions, rng: np.random.Generator) -> TrueDynamics:
    """Draw the true friction and build the injected effects (thesis §3.1.1, §3.4.4).

    Friction and effects draw from separate child generators of ``rng``, so adding an effect
    leaves the friction unchanged.
    """
    rng, effect_rng = rng.spawn(2)
    n = robot.n_joints
    scale, vscale = robot_scales(robot)
    ascale = None
    viscous = _per_joint(options.viscous, 0.1 * scale / vscale * rng.uniform(0.8, 1.2, n), n, "viscous")
    coulomb = _per_joint(options.coulomb, 0.05 * scale * rng.uniform(0.8, 1.2, n), n, "coulomb")
    model = robot.model.copy()
    terms, records, offset = [], [], np.zeros(n)
    g = options.effect_scale
    for req in check_effects(options.effects, "dynamics"):
        if req.name in ("payload", "link_inertia"):
            add = _add_payload if req.name == "payload" else _scale_link
            records.append(add(model, robot, req, effect_rng, g))
            continue
        joint = (
            check_channel(req, robot.joint_names, "joint")
            if req.channel
            else robot.joint_names[int(effect_rng.integers(n))]
        )
        j = robot.joint_index(joint)
        s, v = scale[j] * g, scale[j] / vscale[j] * g
        size = req.size  # N·m (s for torque_lag), see the module docstring
        region = None
        if req.name == "coulomb_friction":
            values = {"coulomb": 0.2 * s if size is None else size}
        elif req.name == "viscous_friction":
            values = {"viscous": 0.3 * v if size is None else size / vscale[j]}
        elif req.name == "position_friction":
            low, high = options.regions.get(joint, default_region(robot, j))
            if not low < high:
                raise SimOptionError(f"position_friction region for {joint!r}: low must be < high, got {low}, {high}")
            region = {"variable": f"q.{joint}", "low": float(low), "high": float(high)}
            if size is None:
                values = {"coulomb": 0.3 * s, "viscous": 0.3 * v}
            else:
                values = {"coulomb": size, "viscous": size / vscale[j]}
        elif req.name == "spring":
            rest = float(robot.neutral()[j])
            span = min(robot.upper[j] - robot.lower[j], 2 * np.pi)
            values = {"stiffness": (0.4 * s if size is None else 2.0 * size) / span, "rest": rest}
        elif req.name == "armature":
            if ascale is None:
                ascale = _accel_scale(robot)
            values = {"inertia": (0.2 * s if size is None else size) / ascale[j]}
            model.armature[j] += values["inertia"]  # a revolute joint: one velocity per joint
        elif req.name == "coupled_friction":
            partner = j - 1 if j > 0 else j + 1
            if not 0 <= partner < n:
                raise SimOptionError(f"coupled_friction needs two joints; robot {robot.name!r} has {n}")
            c = 0.2 * s if size is None else size
            values = {
                "coulomb": c,
                "viscous": (0.1 * v if size is None else 0.5 * size / vscale[j]),
                "ratio": 1.0,
                "partner_index": float(partner),
                "smoothing": COUPLED_SMOOTHING,
            }
        elif req.name == "stribeck_friction":
            values = {"amplitude": 0.2 * s if size is None else size, "velocity_scale": STRIBECK_SCALE}
        elif req.name == "load_friction":
            values = {"coefficient": 0.05 * g if size is None else size}
        elif req.name == "torque_lag":
            values = {"lag": 0.02 if size is None else size}
        elif req.name == "torque_gain":
            values = {"gain_error": float(effect_rng.choice([-1.0, 1.0])) * (0.1 if size is None else size)}
        elif req.name == "transmission_backlash":
            if size is not None and size > MAX_BACKLASH_RAD:
                raise SimOptionError(f"effect '{req}': a backlash's half-width is at most {MAX_BACKLASH_RAD} rad")
            values = {"half_width": 0.02 if size is None else size}
        else:  # torque_offset
            values = {"offset": float(effect_rng.choice([-1.0, 1.0])) * (0.1 * s if size is None else size)}
            offset[j] += values["offset"]
        values = {k: float(x) for k, x in values.items()}
        rec = effect_record(req.name, joint, values, region)
        if req.name == "coupled_friction":
            rec["partner"] = robot.joint_names[int(values["partner_index"])]
        records.append(rec)
        terms.append(EffectTerm(req.name, j, rec))
    return TrueDynamics(model, viscous, coulomb, terms, offset, records)


def _accel_scale(robot) -> np.ndarray:
    """Per-joint RMS acceleration (rad/s²) on :func:`robot_scales`' reference excitation."""
    ref = excitation(robot.lower, robot.upper, time_base(20.0, 50.0), np.random.default_rng(0))
    return np.maximum(np.sqrt((ref.qdd**2).mean(0)), 1e-3)


def _body_frame(model: pin.Model, req):
    """The link of a request on a body (default: the link the last moving joint carries, its first
    body frame: the frames of one joint share its inertia) and its frame."""
    bodies = {f.name: f for f in model.frames if f.type == pin.FrameType.BODY}
    last = max(f.parentJoint for f in bodies.values())
    default = next(name for name, f in bodies.items() if f.parentJoint == last)
    link = check_channel(req, list(bodies), "link") if req.channel else default
    return link, bodies[link]


def _scale_link(model: pin.Model, robot, req, rng, gain: float) -> dict:
    """Scale the body that carries a link (its joint's ten inertial parameters) by 1 − fraction
    (in place; default 0.3); the record holds the fraction and the change, truth less URDF, in the
    registry's names."""
    link, frame = _body_frame(model, req)
    fraction = 0.3 * gain if req.size is None else req.size
    if not 0.0 < fraction < 1.0:
        raise SimOptionError(f"effect '{req}': a link's inertia scaled by 1 − fraction needs 0 < fraction < 1")
    params = model.inertias[frame.parentJoint].toDynamicParameters()
    model.inertias[frame.parentJoint] = pin.Inertia.FromDynamicParameters((1.0 - fraction) * params)
    names = ("mass",) + INERTIAL_NAMES[1:]  # the registry's names of the ten
    change = {n: float(x) for n, x in zip(names, -fraction * params, strict=True)}
    return effect_record("link_inertia", link, {"fraction": float(fraction), **change})


def _add_payload(model: pin.Model, robot, req, rng, gain: float) -> dict:
    """Add a point mass to a link of ``model`` (in place); default: the link the last moving joint
    carries (a payload on the tool flange is one on that link)."""
    link, frame = _body_frame(model, req)
    total = sum(model.inertias[i].mass for i in range(1, model.njoints))
    mass = gain * 0.1 * max(total, 1.0) if req.size is None else req.size
    xyz = rng.uniform(-0.05, 0.05, 3)
    lever = frame.placement.act(xyz)  # in the parent joint's frame
    model.inertias[frame.parentJoint] += pin.Inertia(mass, lever, np.zeros((3, 3)))
    return effect_record(
        "payload",
        link,
        {"mass": float(mass), "x": float(xyz[0]), "y": float(xyz[1]), "z": float(xyz[2])},
    )


def _figure8(robot, options, time, rng, plane):
    """Figure-eight of the last link, centred where the arm is part-folded (thesis Fig. 3.8)."""
    model = robot.model
    kinds = (pin.FrameType.BODY, pin.FrameType.FIXED_JOINT)
    frame = [i for i, f in enumerate(model.frames) if f.type in kinds][-1]
    frac = np.full(robot.n_joints, 0.65)
    frac[0] = 0.5
    q_c = robot.lower + frac * (robot.upper - robot.lower)
    data = model.createData()
    pin.framesForwardKinematics(model, data, q_c)
    # sizes are fractions of the chain's length from the first joint to the frame (1.0 m for arm3)
    reach = np.linalg.norm(model.frames[frame].placement.translation)
    j = model.frames[frame].parentJoint
    while model.parents[j] > 0:
        reach += np.linalg.norm(model.jointPlacements[j].translation)
        j = model.parents[j]
    reach = max(reach, 1e-3)
    centre = data.oMf[frame].translation + reach * rng.uniform(-0.01, 0.01, 3)
    size = reach * np.asarray(options.figure8_size, float) * rng.uniform(0.9, 1.1)
    period = options.figure8_period * rng.uniform(0.9, 1.1)
    return figure_eight(model, frame, time, centre, q_c, plane, tuple(size), period)


def _pole(robot, dyn: TrueDynamics, options, time, rng, up: bool):
    """Reaction-wheel roll-outs (thesis §3.4.2): joint 0 is the passive pole, the others are motors.

    pole-down: multi-sine motor torques of random frequencies from rest hanging down. pole-up:
    LQR about the upright (q₀ = π) on the linearised TRUE dynamics, viscous friction included.
    Both add an Ornstein-Uhlenbeck disturbance torque on the pole (the thesis's process noise).
    """
    n = robot.n_joints
    if n < 2:
        raise RobotConfigError(
            f"trajectory pole-{'up' if up else 'down'} needs a passive pole joint and "
            f"at least one motor; robot {robot.name!r} has {n} joint"
        )
    scale, _ = robot_scales(robot)
    drive = options.drive if options.drive is not None else 0.6 * scale[0]
    sigma = options.disturbance if options.disturbance is not None else 0.05 * scale[0]
    dt = time[1] - time[0]
    dist = ou_noise(time.size, 1, dt, sigma, 0.1, rng)[:, 0]
    actuated = np.arange(1, n)
    q0 = np.zeros(n)
    if not up:
        u, _, _ = sum_of_sines(time, n - 1, rng, drive, f_min=0.2, f_max=2.0)

        def torque(k, q, qd):
            return np.concatenate([[dist[k]], u[k]])

        return rollout(dyn.forward, time, q0, q0, torque)
    q_eq = q0.copy()
    q_eq[0] = np.pi
    A, B = dyn.linearise(q_eq, actuated)
    Q = np.diag(np.concatenate([[100.0], np.full(n - 1, 1e-3), [10.0], np.full(n - 1, 1e-2)]))
    R = np.eye(n - 1) / drive**2
    K = lqr_gain(A, B, Q, R)
    start = q_eq + np.concatenate([[rng.uniform(-0.05, 0.05)], np.zeros(n - 1)])

    def torque(k, q, qd):
        return np.concatenate([[dist[k]], -K @ np.concatenate([q - q_eq, qd])])

    traj = rollout(dyn.forward, time, start, np.zeros(n), torque)
    if np.abs(traj.q[:, 0] - np.pi).max() > 1.0:
        raise NumericalError("pole-up: the LQR lost the balance; lower --disturbance or raise --drive")
    return traj


def _true_baseline(robot, dyn) -> list:
    """The true rigid body (every link's ten inertial parameters, named ``<joint>.<inertial>``) and
    friction as terms of the dynamics baseline (:mod:`diegocal.causes`), in sgp.yaml's form."""
    names = robot.joint_names
    inertial = {
        f"{names[i - 1]}.{p}": float(x)
        for i in range(1, dyn.model.njoints)
        for p, x in zip(INERTIAL_NAMES, dyn.model.inertias[i].toDynamicParameters(), strict=True)
    }
    units = {"m": "kg", "mc": "kg·m", "I": "kg·m²"}
    rigid = make_term("rigid_body", robot.name, inertial)
    rigid = replace(rigid, parameters=tuple(replace(p, unit=units[p.name.rpartition(".")[2].split("_")[0]])
                                            for p in rigid.parameters))
    friction = [make_term("viscous_friction", j, [v]) for j, v in zip(names, dyn.viscous, strict=True)]
    friction += [make_term("coulomb_friction", j, [c]) for j, c in zip(names, dyn.coulomb, strict=True)]
    return [rigid, *friction]


def simulate_dynamics(robot, options: DynamicsOptions, rng: np.random.Generator) -> Log:
    """Simulate a torque log of ``robot`` (streams q, qd, qdd, tau) with ground truth in /truth.

    Returns
    -------
    Log with q (T, n) rad, qd (T, n) rad/s, qdd (T, n) rad/s², tau (T, n) N·m (measured: with
    sensor offset and noise); truth params in sgp.yaml's layout 2, {layout, model, joints,
    baseline: [rigid_body (every link's ten inertial parameters, ``joint.m`` ...), a viscous and a
    Coulomb friction term per joint], noise, trajectory} (:func:`true_friction` reads it), truth
    effects, truth signal ``tau`` (noise-free measured torque).
    """
    if options.trajectory not in TRAJECTORIES:
        raise SimOptionError(f"unknown trajectory {options.trajectory!r}; known: {', '.join(TRAJECTORIES)}")
    if not np.isfinite(options.noise) or options.noise < 0:
        raise SimOptionError(f"noise must be a non-negative torque in N·m, got {options.noise}")
    time = time_base(options.duration, options.rate_hz)
    # independent streams: adding an effect or noise changes nothing else
    model_rng, rng, noise_rng = rng.spawn(3)
    if options.robot_seed is not None:  # another session's robot: the generator that session spawned
        model_rng = np.random.default_rng(options.robot_seed).spawn(3)[0]
    dyn = build_true_dynamics(robot, options, model_rng)
    kind = options.trajectory
    for cause in ("transmission_backlash", "load_friction"):  # the link's angle, its torque: of a known motion
        if kind.startswith("pole-") and any(t.cause == cause for t in dyn.terms):
            raise SimOptionError(f"{cause} is simulated on prescribed trajectories, not {kind}")
    if kind == "excitation":
        traj = excitation(robot.lower, robot.upper, time, rng)
    elif kind == "whirl":
        traj = whirl(robot.lower, robot.upper, time, rng)
    elif kind.startswith("figure8-"):
        traj = _figure8(robot, options, time, rng, kind.split("-")[1])
    else:
        traj = _pole(robot, dyn, options, time, rng, up=kind == "pole-up")
    tau_phys = traj.tau if traj.tau is not None else dyn.inverse(traj.q, traj.qd, traj.qdd)
    tau_clean = dyn.sensor(tau_phys, time)
    tau = tau_clean + options.noise * noise_rng.standard_normal(tau_clean.shape)
    names = robot.joint_names
    streams = {k: make_stream(names, v) for k, v in (("q", traj.q), ("qd", traj.qd), ("qdd", traj.qdd), ("tau", tau))}
    params = {
        "layout": LAYOUT,
        "model": "rigid_body+viscous+coulomb",
        "joints": list(names),
        "baseline": [t.to_dict() for t in _true_baseline(robot, dyn)],
        "noise": {"tau": float(options.noise)},
        "trajectory": kind,
    }
    truth = Truth(params=params, effects=dyn.records, signals={"tau": make_stream(names, tau_clean)})
    return Log(time=time, streams=streams, robot=robot.reference, rate_hz=float(options.rate_hz), truth=truth)
