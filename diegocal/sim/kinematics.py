"""Kinematic calibration data with ground truth: pots and occluded markers (thesis §2.5.1, §2.6).

The robot is hung by its base link from a crane (§2.5.1): every joint is driven by a PID
controller toward random targets within its limits while pots and markers are recorded
synchronously (100 Hz, 250 s for Diego San). Ground truth is drawn around the robot's nominal
sensors.yaml values, as in the thesis' simulation experiments (§2.6):

- pot gains ``gain = nominal · (1 + U(±gain_error))`` (encoders keep gain 1),
- biases ``bias = nominal + gain · U(±bias_error)`` (rad of joint angle; scaled to the
  transmission's spread for linear pots and tendons),
- marker positions a few cm from the nominal ones (which may be link origins, §2.7.1),
- a random mocap frame (R, T0).

Readings follow the observation models of :mod:`diegocal.robot.observe` (eq. 2.11-2.20)::

    p_t = gain · s(q_t) + bias + ε_p            ε_p ~ N(0, pot_noise²)             [V]
    x_t = R (h_r(q_t) d + h_p(q_t)) + T0 + ε_x  ε_x ~ N(0, marker_noise² I₃)       [m]

Markers are NaN over contiguous occlusion runs (a two-state Markov chain per marker).
Kinematic effects from DESIGN.md's vocabulary are injected by name (:func:`plan_effects`), with
the simulator's physical default ranges or the size a request gives (:data:`SIZE_UNITS`), and
recorded in ``/truth`` with their true values. Two of them corrupt the mocap stream itself, as
labelling errors of a real motion-capture session do: ``marker_outliers`` (ghost markers and
reflections: a reading a few cm to dm off for a few samples) and ``swapped_labels`` (two nearby
markers exchange labels for runs of a fraction of a second); ``/truth`` then also holds the
signal ``markers_corrupted`` (T, M), 1 where a reading is not its own marker's.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.linalg import expm
from scipy.spatial.transform import Rotation

from diegocal.causes import KINEMATIC_SIZE_UNITS
from diegocal.errors import RobotConfigError
from diegocal.io import Log, Truth, make_stream
from diegocal.robot import PointSet, Robot, pot_transmission
from diegocal.robot.batch import BatchKinematics
from diegocal.robot.model import shift_joint_origins
from diegocal.sim.effects import (
    EffectRequest,
    SimOptionError,
    check_effects,
)
from diegocal.sim.kinematic_effects import backlash, bias_scale, corrupt_labels, plan_effects, record_displacement
from diegocal.stac.calibration import Calibration

#: Extra samples simulated on each side so a mocap clock offset has data to shift into (a
#: requested shift longer than this simulates a longer run, so the joints then move differently
#: from a run of the same seed without it).
PAD = 16

#: What ``--effect CAUSE:CHANNEL=SIZE`` sizes, per cause (:data:`diegocal.causes.KINEMATIC_SIZE_UNITS`).
SIZE_UNITS = KINEMATIC_SIZE_UNITS


@dataclass(frozen=True)
class KinematicsOptions:
    """Options of :func:`simulate_kinematics` (the CLI parses its flags into one of these).

    Attributes
    ----------
    duration : float, s (thesis: 250 s for Diego San)
    rate_hz : float, sample rate of pots and markers, Hz (thesis: 100 Hz)
    effects : tuple of EffectRequest, kinematic effects to inject
    occlusion : float in [0, 0.95), target fraction of occluded marker samples
    occlusion_run : float, mean length of one occlusion, s
    gain_error : float, relative half-width of the true gain around the nominal one
    bias_error : float, half-width of the true bias error, rad of joint angle
    marker_offset : float, m, mean distance of the true marker positions from the nominal ones
    pot_noise : float, standard deviation of pot noise, sensor units (V)
    marker_noise : float, standard deviation of marker noise per axis, m
    hold : (float, float), s, range of the time a joint holds one random target
    directions : joint -> (3,) direction of that joint's ``link_offset`` in its parent joint's
        frame (normalised here; e.g. the joint's URDF origin: the link is longer or shorter);
        a joint not named gets a random direction
    robot_seed : int or None, the seed whose robot this session records: its true calibration
        and mocap frame, and its effects drawn as that session draws them (a slip or a label swap
        at the same share of the run), with this session's own motion, noise and occlusions;
        None: this session's own seed. That session is taken at this one's duration: the biases of
        linear pots and tendons scale with the run's spread, so a session of another length records
        them a little differently
    """

    duration: float = 250.0
    rate_hz: float = 100.0
    effects: tuple[EffectRequest, ...] = ()
    occlusion: float = 0.1
    occlusion_run: float = 0.5
    gain_error: float = 0.2
    bias_error: float = 0.3
    marker_offset: float = 0.03
    pot_noise: float = 0.005
    marker_noise: float = 0.002
    hold: tuple[float, float] = (0.5, 3.0)
    directions: dict = field(default_factory=dict)
    robot_seed: int | None = None

    @property
    def n_samples(self) -> int:
        return int(round(self.duration * self.rate_hz))

    def check(self) -> KinematicsOptions:
        """Validate ranges; raises :class:`SimOptionError` naming the bad option."""
        if not np.isfinite(self.duration) or self.duration <= 0:
            raise SimOptionError(f"duration must be positive, got {self.duration} s")
        if not np.isfinite(self.rate_hz) or self.rate_hz <= 0:
            raise SimOptionError(f"rate must be positive, got {self.rate_hz} Hz")
        if self.n_samples < 2:
            raise SimOptionError(f"duration {self.duration} s at {self.rate_hz} Hz gives fewer than 2 samples")
        if not 0.0 <= self.occlusion < 0.95:
            raise SimOptionError(f"occlusion fraction must be in [0, 0.95), got {self.occlusion}")
        if not self.occlusion_run > 0:
            raise SimOptionError(f"occlusion run must be positive, got {self.occlusion_run} s")
        for name in ("gain_error", "bias_error", "marker_offset", "pot_noise", "marker_noise"):
            value = getattr(self, name)
            if not np.isfinite(value) or value < 0:
                raise SimOptionError(f"{name.replace('_', '-')} must be >= 0, got {value}")
        if self.gain_error >= 1:
            raise SimOptionError(f"gain-error must be < 1 (a gain may not flip sign), got {self.gain_error}")
        if not 0 < self.hold[0] <= self.hold[1]:
            raise SimOptionError(f"hold must be 0 < low <= high, got {self.hold}")
        check_effects(self.effects, "kinematics")
        offsets = {e.channel for e in self.effects if e.name == "link_offset"}
        for joint, d in self.directions.items():
            d = np.asarray(d, float)
            if d.shape != (3,) or not np.all(np.isfinite(d)) or not np.linalg.norm(d) > 0:
                raise SimOptionError(f"direction of {joint}'s link offset must be 3 finite numbers, not all 0; got {d}")
            if joint not in offsets:
                raise SimOptionError(f"a direction is given for {joint} but no link_offset:{joint} is requested")
        return self


# ----------------------------------------------------------------------------- trajectory
def joint_ranges(robot: Robot) -> tuple[np.ndarray, np.ndarray]:
    """Usable joint ranges (n,), (n,): the URDF limits, or neutral ± π where they are unbounded."""
    lo, hi = robot.lower.copy(), robot.upper.copy()
    bad = ~np.isfinite(lo) | ~np.isfinite(hi) | (hi - lo > 4 * np.pi) | (hi <= lo)
    mid = robot.neutral()
    mid[bad] = 0.0
    lo[bad], hi[bad] = mid[bad] - np.pi, mid[bad] + np.pi
    return lo, hi


def pid_trajectory(
    lower, upper, n_samples: int, rate_hz: float, rng: np.random.Generator, hold=(0.5, 3.0)
) -> tuple[np.ndarray, np.ndarray]:
    """Joints driven by PID controllers toward random targets (thesis §2.5.1).

    Each joint is a unit-inertia second-order plant under PID control,

    .. math:: \\ddot q = k_p (r - q) + k_i \\int (r - q)\\,dt - k_d \\dot q,

    with :math:`k_p = \\omega^2`, :math:`k_d = 2\\zeta\\omega`, :math:`k_i = 0.25\\omega^3`,
    ω ~ U(2.5, 6) rad/s and ζ ~ U(0.7, 1) per joint (stable: k_d k_p > k_i). The closed loop is
    discretised exactly (zero-order hold on the target) and stepped for all joints at once;
    the limits act as hard stops. Targets r are uniform within the inner 90 % of each range
    and held for U(hold) seconds.

    Parameters
    ----------
    lower, upper : (n,) joint limits, rad or m
    n_samples : int, T
    rate_hz : float, Hz

    Returns
    -------
    q : ndarray (T, n), rad or m;  qd : ndarray (T, n), rad/s or m/s
    """
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    n = lower.size
    dt = 1.0 / rate_hz
    omega = rng.uniform(2.5, 6.0, n)
    zeta = rng.uniform(0.7, 1.0, n)
    kp, kd, ki = omega**2, 2 * zeta * omega, 0.25 * omega**3
    # state x = [q, qd, ∫e]; x' = A x + B r
    A = np.zeros((n, 3, 3))
    A[:, 0, 1] = 1.0
    A[:, 1, 0], A[:, 1, 1], A[:, 1, 2] = -kp, -kd, ki
    A[:, 2, 0] = -1.0
    B = np.stack([np.zeros(n), kp, np.ones(n)], axis=1)
    aug = np.zeros((n, 4, 4))
    aug[:, :3, :3], aug[:, :3, 3] = A * dt, B * dt
    disc = np.stack([expm(a) for a in aug])
    Ad, Bd = disc[:, :3, :3], disc[:, :3, 3]

    span = upper - lower
    targets = _random_targets(lower + 0.05 * span, upper - 0.05 * span, n_samples, rate_hz, rng, hold)
    x = np.zeros((n, 3))
    x[:, 0] = targets[0]
    q = np.empty((n_samples, n))
    qd = np.empty((n_samples, n))
    for t in range(n_samples):
        q[t], qd[t] = x[:, 0], x[:, 1]
        x = np.einsum("nij,nj->ni", Ad, x) + Bd * targets[t][:, None]
        hit = (x[:, 0] < lower) | (x[:, 0] > upper)
        if hit.any():  # hard stop: clamp and lose the velocity
            x[hit, 0] = np.clip(x[hit, 0], lower[hit], upper[hit])
            x[hit, 1] = 0.0
    return q, qd


def _random_targets(lo, hi, n_samples, rate_hz, rng, hold) -> np.ndarray:
    """(T, n) piecewise-constant targets: a new uniform target every U(hold) seconds per joint."""
    n = lo.size
    out = np.empty((n_samples, n))
    k = int(n_samples / max(hold[0] * rate_hz, 1.0)) + 2
    for j in range(n):
        lengths = np.maximum(1, np.round(rng.uniform(hold[0], hold[1], k) * rate_hz)).astype(int)
        values = rng.uniform(lo[j], hi[j], k)
        out[:, j] = np.repeat(values, lengths)[:n_samples]
    return out


# ----------------------------------------------------------------------------- occlusion
def occlusion_mask(
    n_samples: int, n_markers: int, fraction: float, mean_run: float, rng: np.random.Generator
) -> np.ndarray:
    """Occlusion runs from a two-state Markov chain per marker, vectorised over runs.

    Occluded runs last Geometric(1/L) samples (mean L = ``mean_run`` samples); visible runs
    Geometric(f / (L (1 - f))), so the stationary occluded fraction is f = ``fraction``. The
    first state is drawn from the stationary distribution.

    Returns
    -------
    ndarray of bool, shape (T, M): True where the marker is occluded.
    """
    mask = np.zeros((n_samples, n_markers), dtype=bool)
    if fraction <= 0 or n_markers == 0:
        return mask
    L = max(float(mean_run), 1.0)
    p_end_occ = 1.0 / L
    p_end_vis = min(1.0, fraction / (L * (1.0 - fraction)))
    n_runs = int(n_samples * min(p_end_occ, p_end_vis)) + 8
    for m in range(n_markers):
        state = bool(rng.random() < fraction)  # stationary start
        chunks, filled = [], 0
        while filled < n_samples:  # a chunk ends in the state opposite to the one it starts in
            occ = rng.geometric(p_end_occ, n_runs)
            vis = rng.geometric(p_end_vis, n_runs)
            lengths = np.stack([occ, vis] if state else [vis, occ], axis=1).ravel()
            chunks.append(np.repeat(np.tile([state, not state], n_runs), lengths))
            filled += int(lengths.sum())
        mask[:, m] = np.concatenate(chunks)[:n_samples]
    return mask


# ----------------------------------------------------------------------------- truth
def draw_truth(
    robot: Robot, options: KinematicsOptions, s: np.ndarray, q: np.ndarray, rng: np.random.Generator
) -> Calibration:
    """True sensor parameters around the nominal ones (see the module docstring).

    ``s`` (T, P) is the transmission quantity and ``q`` (T, n) the joint angles of the run,
    used only to scale bias errors of linear pots and tendons.
    """
    nominal = Calibration.nominal(robot)
    P, M = len(nominal.pot_names), len(nominal.marker_names)
    encoder = np.array([p.kind == "encoder" for p in robot.sensors.pots], dtype=bool)
    gain = nominal.gain * (1.0 + rng.uniform(-options.gain_error, options.gain_error, P))
    gain[encoder] = 1.0
    offset = rng.uniform(-options.bias_error, options.bias_error, P) * bias_scale(robot, s, q)
    bias = nominal.bias + gain * offset
    direction = rng.normal(size=(M, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    distance = options.marker_offset * rng.uniform(0.5, 1.5, (M, 1))
    xyz = nominal.marker_xyz + direction * distance
    R = Rotation.random(random_state=rng).as_matrix()
    T = rng.uniform([-1.0, -1.0, 0.5], [1.0, 1.0, 1.5])
    return Calibration(
        pot_names=nominal.pot_names,
        gain=gain,
        bias=bias,
        marker_names=nominal.marker_names,
        marker_links=nominal.marker_links,
        marker_xyz=xyz,
        mocap_R=R,
        mocap_T=T,
        sigma_pots=options.pot_noise,
        sigma_markers=options.marker_noise,
        method="truth",
        pot_units=nominal.pot_units,
    )


# ----------------------------------------------------------------------------- effects
class BatchedRobot(Robot):
    """A :class:`Robot` whose ``points`` is :func:`base_points` (same result, vectorised over
    frames), so the library's observation models (``pot_transmission``) run batched too."""

    def points(self, q, points: PointSet) -> np.ndarray:
        return base_points(self, q, points.links, points.xyz)


def offset_robot(robot: Robot, offsets: dict) -> BatchedRobot:
    """A batched copy of ``robot`` whose named joints' origins are shifted by (3,) m vectors (its
    locked and continuous joints and source kept, as :meth:`Robot.with_model` keeps them)."""
    model = shift_joint_origins(robot.model, offsets)
    return BatchedRobot(model, robot.sensors, robot.name, robot.directory, locked=robot.locked,
                        source=robot.source, continuous=robot.continuous)


# ----------------------------------------------------------------------------- simulator
def simulate_kinematics(robot: Robot, options: KinematicsOptions, rng: np.random.Generator) -> Log:
    """Simulate a kinematic calibration session (thesis §2.5.1) with ground truth.

    Parameters
    ----------
    robot : Robot, with pots and/or markers in its sensors.yaml
    options : KinematicsOptions
    rng : numpy Generator; the same seed gives the same log, bit for bit

    Returns
    -------
    Log with streams ``pots`` (T, P) [V] and ``markers`` (T, M, 3) [m, NaN when occluded], and
    ``truth``: params = the true :class:`Calibration` as calib.yaml, effects = injected effects,
    signals ``q`` (T, n) and ``qd`` (T, n) on the pots' clock.
    """
    options.check()
    sensors = robot.sensors
    if not sensors.pots and not sensors.markers:
        raise RobotConfigError(f"robot {robot.name!r} has no pots and no markers: nothing to simulate")
    T, rate = options.n_samples, options.rate_hz
    seeds = rng.integers(0, 2**62, size=6)
    traj_rng, truth_rng, pot_rng, marker_rng, occ_rng = (np.random.default_rng(s) for s in seeds[:5])

    lower, upper = joint_ranges(robot)
    shifts = [e.size * rate for e in options.effects if e.name == "time_offset" and e.size is not None]
    pad = max([PAD, *[int(np.ceil(k)) + 2 for k in shifts]])
    q_ext, qd_ext = pid_trajectory(lower, upper, T + 2 * pad, rate, traj_rng, options.hold)
    q, qd = q_ext[pad : pad + T], qd_ext[pad : pad + T]
    fast = offset_robot(robot, {})
    s_nominal = pot_transmission(fast, q) if sensors.pots else np.zeros((T, 0))
    q_robot, s_robot, effect_seed = q, s_nominal, int(seeds[5])
    if options.robot_seed is not None:  # another session's robot: drawn from that session's run
        robot_seeds = np.random.default_rng(options.robot_seed).integers(0, 2**62, size=6)
        q_other, _ = pid_trajectory(lower, upper, T + 2 * pad, rate, np.random.default_rng(robot_seeds[0]),
                                    options.hold)
        q_robot = q_other[pad : pad + T]
        s_robot = pot_transmission(fast, q_robot) if sensors.pots else np.zeros((T, 0))
        truth_rng, effect_seed = np.random.default_rng(robot_seeds[1]), int(robot_seeds[5])
    truth = draw_truth(robot, options, s_robot, q_robot, truth_rng)
    swaps = any(e.name == "swapped_labels" for e in options.effects)
    x_nominal = marker_positions(fast, q_robot, truth) if swaps and sensors.markers else None
    plan = plan_effects(robot, options, s_robot, q_robot, truth.gain, effect_seed, x_nominal)
    gen = offset_robot(robot, plan.joint_offsets)

    streams = {}
    if sensors.pots:
        s = pot_transmission(gen, q) if plan.joint_offsets else s_nominal.copy()
        for i, width in plan.backlash.items():
            s[:, i] = backlash(s[:, i], width)
        p = truth.gain * s + truth.bias  # eq. 2.18-2.20
        for i, (s0, c2) in plan.nonlinear.items():
            p[:, i] += c2 * (s[:, i] - s0) ** 2
        p += pot_rng.normal(0.0, options.pot_noise, p.shape)
        streams["pots"] = make_stream(sensors.pot_names, p)
    if sensors.markers:
        q_mocap = mocap_clock(q_ext, pad, T, plan.shift)
        x = marker_positions(gen, q_mocap, truth, plan.slips)
        if plan.shift:
            record_displacement(plan, x, marker_positions(gen, q, truth, plan.slips))
        x += marker_rng.normal(0.0, options.marker_noise, x.shape)
        x, corrupted = corrupt_labels(x, plan)
        mask = occlusion_mask(T, len(sensors.markers), options.occlusion, options.occlusion_run * rate, occ_rng)
        x[mask] = np.nan
        corrupted &= ~mask
        streams["markers"] = make_stream(sensors.marker_names, x)

    signals = {"q": make_stream(robot.joint_names, q), "qd": make_stream(robot.joint_names, qd)}
    if plan.outliers or plan.swaps:
        signals["markers_corrupted"] = make_stream(sensors.marker_names, corrupted.astype(float))
    name = robot.reference  # a bundled robot's name, else its directory: --robot defaults to it
    return Log(
        time=np.arange(T) / rate,
        streams=streams,
        robot=name,
        rate_hz=rate,
        truth=Truth(params=truth.to_dict(), effects=plan.records, signals=signals),
    )


def mocap_clock(q_ext: np.ndarray, pad: int, T: int, shift: float) -> np.ndarray:
    """Joint angles (T, n) at the mocap's samples, q(t + shift) for the run that starts ``pad``
    samples into ``q_ext``: a slice for a whole-sample shift, else a cubic spline through the
    simulated samples (the trajectory is smooth between them)."""
    if float(shift).is_integer():
        k = int(shift)
        return q_ext[pad + k : pad + k + T]
    return CubicSpline(np.arange(q_ext.shape[0]), q_ext, axis=0)(pad + shift + np.arange(T))


def marker_positions(robot: Robot, q: np.ndarray, truth: Calibration, slips: dict | None = None) -> np.ndarray:
    """Noise-free markers in the mocap frame (T, M, 3), m, thesis eq. 2.11-2.12.

    ``slips`` maps a marker index to (sample, (3,) m): from that sample on, the marker sits
    at ``xyz + dxyz`` on its link.
    """
    slips = slips or {}
    links = list(truth.marker_links)
    xyz = [truth.marker_xyz]
    for m, (_, d) in slips.items():
        links.append(truth.marker_links[m])
        xyz.append((truth.marker_xyz[m] + d)[None])
    xb = base_points(robot, q, links, np.vstack(xyz))
    M = len(truth.marker_names)
    for k, (m, (t_slip, _)) in enumerate(slips.items()):
        xb[t_slip:, m] = xb[t_slip:, M + k]
    return xb[:, :M] @ np.asarray(truth.mocap_R).T + np.asarray(truth.mocap_T)


def base_points(robot: Robot, q: np.ndarray, links, xyz: np.ndarray) -> np.ndarray:
    """Link-fixed points in the base frame (T, N, 3), m — :meth:`Robot.points`, vectorised over
    frames by :class:`diegocal.robot.batch.BatchKinematics`."""
    kin = BatchKinematics(robot)
    return kin.points(kin.joint_poses(robot.check_q(q)), PointSet(tuple(links), np.asarray(xyz, float)))
