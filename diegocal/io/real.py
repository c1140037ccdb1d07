"""Real-robot logs (Stäubli TX40, PAL TIAGo) converted to diegocal logs with q, qd, qdd, tau.

The recordings and their unit facts are described in ``shared/data/real/README.md`` (from the
FIGAROH examples). This module applies those documented conversions and nothing else:

TX40 (5 kHz, motor side):
    motor = R · q with R = diag(32, 32, 45, −48, 45, 32) and the wrist coupling R[5, 4] = 32
    (motor 6 = 32 (q5 + q6)); then q2 −= π/2, q3 += π/2 to match ``tx40.urdf``'s zero.
    Joint torque τ = Rᵀ c for motor torques c (N·m, drive gain 1).

TIAGo (≈100 Hz with 7.7-12.3 ms jitter):
    τ = gain × effort with net gains arm_1, arm_2: 13.6; arm_3, arm_4: −8.7; arm_5..7: −20.6
    (the original authors' assumptions). The torso force is effort + g × m_carried with
    m_carried ≈ 18.5 kg. The wrist efforts (arm_5..7) are exactly 0 in ~90 % of samples: they
    are unusable, and by default left out of the ``tau`` stream (``q``/``qd``/``qdd`` keep all
    eight joints).

Derivatives (both robots): positions are put on a uniform time base (TIAGo: linear
interpolation), low-passed by a zero-phase Butterworth filter (``scipy.signal.sosfiltfilt``,
order 4 forward and backward, so no lag), differentiated by central differences
(``numpy.gradient``) and low-passed again after each differentiation. Torques go through the
same filter, so τ and q̈ share one bandwidth. TX40 is then decimated to ``rate_hz`` (the filter
is the anti-alias filter). The log is cropped to the excitation window (:func:`excitation_window`),
keeping the recording's own time stamps. On TIAGo the detected window (6.6-68.4 s) is wider than
the README's 9.2-67.9 s: the arm already moves at up to 0.19 rad/s from 6.8 s; pass
``RealOptions(window=(9.2, 67.9))`` for the README's rows 921-6791.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.signal import butter, sosfiltfilt
from scipy.spatial.transform import Rotation

from diegocal.errors import InputFileError, LogFormatError
from diegocal.io.log import Log, make_stream

GRAVITY = 9.81  # m/s², the README's value

# ----------------------------------------------------------------------------- TX40 constants
TX40_JOINTS = tuple(f"joint_{i}" for i in range(1, 7))
TX40_RATE_HZ = 5000.0
#: motor = TX40_RATIO @ q (README: diag(32, 32, 45, −48, 45, 32) plus wrist coupling R[5, 4] = 32).
TX40_RATIO = np.diag([32.0, 32.0, 45.0, -48.0, 45.0, 32.0])
TX40_RATIO[5, 4] = 32.0
#: Added to the joint angles after the ratio so they match tx40.urdf's zero, rad.
TX40_ZERO = np.array([0.0, -np.pi / 2, np.pi / 2, 0.0, 0.0, 0.0])

# ----------------------------------------------------------------------------- TIAGo constants
TIAGO_JOINTS = ("torso_lift_joint",) + tuple(f"arm_{i}_joint" for i in range(1, 8))
#: Net effort -> torque gain (ratio × k_motor), README; the torso's effort is already in N.
TIAGO_EFFORT_GAIN = {"torso_lift_joint": 1.0, "arm_1_joint": 13.6, "arm_2_joint": 13.6,
                     "arm_3_joint": -8.7, "arm_4_joint": -8.7, "arm_5_joint": -20.6,
                     "arm_6_joint": -20.6, "arm_7_joint": -20.6}
#: Mass carried by the torso lift, kg (README: about 18.5 kg with tiago_hey5.urdf).
TIAGO_TORSO_MASS = 18.5
#: Joints whose effort is unusable (exactly zero in ~90 % of samples, 0.001 steps).
TIAGO_UNUSABLE_TAU = ("arm_5_joint", "arm_6_joint", "arm_7_joint")


@dataclass(frozen=True)
class RealOptions:
    """Conversion options.

    Attributes
    ----------
    cutoff_hz : float, cut-off of the zero-phase Butterworth low-pass, Hz
    order : int, Butterworth order of one pass (sosfiltfilt doubles it)
    rate_hz : float or None, output rate (TX40 decimation); None keeps the native rate
    crop : bool, cut the log to the excitation window
    threshold : float, rad/s (or m/s), joint speed that counts as moving
    margin_s : float, s, kept before and after the detected motion
    window : (float, float) or None, s: an explicit window (recording time) instead of detection
    """

    cutoff_hz: float = 10.0
    order: int = 4
    rate_hz: float | None = None
    crop: bool = True
    threshold: float = 0.02
    margin_s: float = 0.25
    window: tuple[float, float] | None = None


TX40_DEFAULTS = RealOptions(cutoff_hz=10.0, rate_hz=200.0)
TIAGO_DEFAULTS = RealOptions(cutoff_hz=5.0, rate_hz=None)


# ----------------------------------------------------------------------------- conversions
def tx40_joint_from_motor(motor) -> np.ndarray:
    """Joint angles (T, 6) rad from motor-side angles (T, 6) rad: q = R⁻¹ motor + zero."""
    motor = _check_columns(motor, 6, "TX40 motor positions")
    return np.linalg.solve(TX40_RATIO, motor.T).T + TX40_ZERO


def tx40_torque_from_motor(current) -> np.ndarray:
    """Joint torques (T, 6) N·m from motor torques (T, 6) N·m: τ = Rᵀ c (τ5 = 45 c5 + 32 c6)."""
    current = _check_columns(current, 6, "TX40 motor torques")
    return current @ TX40_RATIO


def tiago_torque_from_effort(effort, torso_mass: float = TIAGO_TORSO_MASS) -> np.ndarray:
    """Joint torques (T, 8), N (torso) and N·m (arm), from efforts (T, 8) in TIAGO_JOINTS order.

    τ_arm = gain × effort; torso force = effort + g × ``torso_mass`` (kg).
    """
    effort = _check_columns(effort, len(TIAGO_JOINTS), "TIAGo efforts")
    gain = np.array([TIAGO_EFFORT_GAIN[j] for j in TIAGO_JOINTS])
    tau = effort * gain
    tau[:, 0] += GRAVITY * torso_mass
    return tau


def lowpass(x: np.ndarray, rate_hz: float, cutoff_hz: float, order: int = 4) -> np.ndarray:
    """Zero-phase Butterworth low-pass along axis 0 (forward-backward, no lag)."""
    if not 0 < cutoff_hz < 0.5 * rate_hz:
        raise ValueError(f"cut-off must be in (0, {0.5 * rate_hz}) Hz, got {cutoff_hz}")
    sos = butter(order, cutoff_hz, fs=rate_hz, output="sos")
    return sosfiltfilt(sos, x, axis=0)


def smooth_derivatives(q: np.ndarray, rate_hz: float, cutoff_hz: float, order: int = 4):
    """Filtered q, qd, qdd (each (T, n)) from uniformly sampled positions (T, n).

    Zero-phase low-pass, central difference, low-pass again (per derivative).
    """
    dt = 1.0 / rate_hz
    qf = lowpass(q, rate_hz, cutoff_hz, order)
    qd = lowpass(np.gradient(qf, dt, axis=0), rate_hz, cutoff_hz, order)
    qdd = lowpass(np.gradient(qd, dt, axis=0), rate_hz, cutoff_hz, order)
    return qf, qd, qdd


def excitation_window(qd: np.ndarray, rate_hz: float, threshold: float = 0.02,
                      margin_s: float = 0.25) -> tuple[int, int]:
    """Sample range [start, stop) where any joint moves faster than ``threshold``, ± margin.

    ``qd`` (T, n) in rad/s (m/s); the whole range when nothing moves.
    """
    moving = np.flatnonzero(np.abs(qd).max(axis=1) > threshold)
    if moving.size == 0:
        return 0, qd.shape[0]
    pad = int(round(margin_s * rate_hz))
    return max(0, int(moving[0]) - pad), min(qd.shape[0], int(moving[-1]) + 1 + pad)


# ----------------------------------------------------------------------------- loaders
def load_tx40(directory, options: RealOptions = TX40_DEFAULTS) -> Log:
    """The TX40 run as a diegocal log: q, qd, qdd, tau at ``options.rate_hz`` (default 200 Hz).

    Reads ``pos_read_data.csv`` and ``curr_data.csv`` (45,000 rows at 5 kHz, no time column).
    """
    directory = Path(directory)
    motor = _read_table(directory / "pos_read_data.csv", [f"Joint_{i}" for i in range(1, 7)])
    current = _read_table(directory / "curr_data.csv", [f"Joint_{i}" for i in range(1, 7)])
    if motor.shape != current.shape:
        raise LogFormatError(f"{directory}: positions have {motor.shape[0]} rows, torques "
                             f"{current.shape[0]}")
    q = tx40_joint_from_motor(motor)
    tau = tx40_torque_from_motor(current)
    time = np.arange(q.shape[0]) / TX40_RATE_HZ
    return _finish("tx40", TX40_JOINTS, time, TX40_RATE_HZ, q, tau, TX40_JOINTS, options)


def load_tiago(directory, options: RealOptions = TIAGO_DEFAULTS, wrist_tau: bool = False,
               torso_mass: float = TIAGO_TORSO_MASS) -> Log:
    """The TIAGo run as a diegocal log on a uniform 100 Hz time base.

    Reads ``tiago_position.csv`` and ``tiago_effort.csv`` (columns ``t`` and
    ``- <joint>_position|_effort``; the controller's velocity file is not used). ``tau`` has the
    torso and arm_1..4 only unless ``wrist_tau`` (arm_5..7 efforts are unusable, README).
    """
    directory = Path(directory)
    pos_cols = ["t"] + [f"- {j}_position" for j in TIAGO_JOINTS]
    eff_cols = ["t"] + [f"- {j}_effort" for j in TIAGO_JOINTS]
    pos = _read_table(directory / "tiago_position.csv", pos_cols)
    eff = _read_table(directory / "tiago_effort.csv", eff_cols)
    if pos.shape != eff.shape or not np.array_equal(pos[:, 0], eff[:, 0]):
        raise LogFormatError(f"{directory}: position and effort files have different time stamps")
    t = pos[:, 0]
    if (np.diff(t) <= 0).any():
        raise LogFormatError(f"{directory}/tiago_position.csv: time is not strictly increasing")
    rate = float(round(1.0 / np.median(np.diff(t))))
    time = t[0] + np.arange(int(np.floor((t[-1] - t[0]) * rate)) + 1) / rate
    q = _interp(time, t, pos[:, 1:])
    tau = _interp(time, t, tiago_torque_from_effort(eff[:, 1:], torso_mass))
    keep = TIAGO_JOINTS if wrist_tau else tuple(j for j in TIAGO_JOINTS
                                                if j not in TIAGO_UNUSABLE_TAU)
    tau = tau[:, [TIAGO_JOINTS.index(j) for j in keep]]
    return _finish("tiago", TIAGO_JOINTS, time, rate, q, tau, keep, options)


def _finish(robot, joints, time, rate, q, tau, tau_joints, options: RealOptions) -> Log:
    """Filter, differentiate, decimate and crop; build the log."""
    qf, qd, qdd = smooth_derivatives(q, rate, options.cutoff_hz, options.order)
    tauf = lowpass(tau, rate, options.cutoff_hz, options.order)
    step = 1
    if options.rate_hz is not None and options.rate_hz < rate:
        step = int(round(rate / options.rate_hz))
    arrays = [a[::step] for a in (time, qf, qd, qdd, tauf)]
    out_rate = rate / step
    start, stop = 0, arrays[0].shape[0]
    if options.window is not None:
        lo, hi = options.window
        start, stop = np.searchsorted(arrays[0], [lo, hi])
        if stop - start < 2:
            raise LogFormatError(f"window {options.window} s holds fewer than 2 samples "
                             f"(log spans {arrays[0][0]:.3f}..{arrays[0][-1]:.3f} s)")
    elif options.crop:
        start, stop = excitation_window(arrays[2], out_rate, options.threshold, options.margin_s)
    time, qf, qd, qdd, tauf = (a[start:stop] for a in arrays)
    streams = {"q": make_stream(joints, qf), "qd": make_stream(joints, qd),
               "qdd": make_stream(joints, qdd), "tau": make_stream(tau_joints, tauf)}
    return Log(time=np.ascontiguousarray(time), streams=streams, robot=robot, rate_hz=out_rate)


def _interp(time, t, x) -> np.ndarray:
    return np.stack([np.interp(time, t, x[:, k]) for k in range(x.shape[1])], axis=1)


def _check_columns(x, k: int, what: str) -> np.ndarray:
    x = np.asarray(x, dtype=float)
    if x.ndim != 2 or x.shape[1] != k:
        raise ValueError(f"{what}: expected shape (T, {k}), got {x.shape}")
    return x


def _read_table(path: Path, columns) -> np.ndarray:
    """The named columns of a CSV as float64 (T, K); one clear error when absent or non-numeric."""
    import pandas as pd

    if not path.exists():
        raise InputFileError(f"{path}: no such file")
    try:
        frame = pd.read_csv(path)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise LogFormatError(f"{path}: cannot parse CSV ({str(exc).splitlines()[0]})") from None
    missing = [c for c in columns if c not in frame.columns]
    if missing:
        raise LogFormatError(f"{path}: missing columns {missing}")
    try:
        data = frame[list(columns)].to_numpy(dtype=np.float64)
    except (ValueError, TypeError):
        raise LogFormatError(f"{path}: non-numeric values") from None
    if not np.isfinite(data).all():
        raise LogFormatError(f"{path}: NaN or infinite values")
    return data


# ----------------------------------------------------------------------------- URDF reduction
def reduce_urdf(src, dst, keep, name: str | None = None) -> dict:
    """Write a URDF where only the joints in ``keep`` move; every other joint becomes fixed.

    A fixed joint is frozen at its neutral value (0, clamped into its limits): its rotation
    (or translation) at that value is folded into the joint's ``<origin>``. Mimic tags go,
    kept continuous joints become revolute in [−π, π] (diegocal accepts only 1-DoF joints),
    and ``<transmission>``/``<gazebo>`` blocks are dropped. Returns {joint: frozen value}.
    """
    src, dst = Path(src), Path(dst)
    if not src.exists():
        raise InputFileError(f"{src}: no such file")
    try:
        tree = ET.parse(src)
    except ET.ParseError as exc:
        raise InputFileError(f"{src}: not valid XML ({exc})") from None
    root = tree.getroot()
    keep = set(keep)
    found = {j.get("name") for j in root.findall("joint")}
    if keep - found:
        raise InputFileError(f"{src}: no joints {sorted(keep - found)}")
    for tag in ("transmission", "gazebo"):
        for el in root.findall(tag):
            root.remove(el)
    frozen = {}
    for joint in root.findall("joint"):
        kind = joint.get("type")
        for mimic in joint.findall("mimic"):
            joint.remove(mimic)
        if joint.get("name") in keep:
            if kind == "continuous":
                joint.set("type", "revolute")
                limit = joint.find("limit")
                if limit is None:
                    limit = ET.SubElement(joint, "limit", effort="0", velocity="0")
                limit.set("lower", str(-np.pi))
                limit.set("upper", str(np.pi))
            continue
        if kind == "fixed":
            continue
        value = _neutral(joint)
        if value != 0.0:
            _fold_into_origin(joint, kind, value)
        frozen[joint.get("name")] = value
        joint.set("type", "fixed")
        for tag in ("axis", "limit", "dynamics", "safety_controller", "calibration"):
            for el in joint.findall(tag):
                joint.remove(el)
    if name:
        root.set("name", name)
    dst.parent.mkdir(parents=True, exist_ok=True)
    from diegocal.io.files import atomic_path

    with atomic_path(dst) as tmp:
        tree.write(tmp, encoding="utf-8", xml_declaration=True)
    return frozen


def _neutral(joint) -> float:
    limit = joint.find("limit")
    if joint.get("type") == "continuous" or limit is None:
        return 0.0
    lo, hi = float(limit.get("lower", 0.0)), float(limit.get("upper", 0.0))
    return float(np.clip(0.0, lo, hi))


def _fold_into_origin(joint, kind: str, value: float) -> None:
    """origin ← origin · motion(axis, value) for a revolute or prismatic joint."""
    origin = joint.find("origin")
    if origin is None:
        origin = ET.SubElement(joint, "origin", xyz="0 0 0", rpy="0 0 0")
    xyz = np.array([float(v) for v in origin.get("xyz", "0 0 0").split()])
    rpy = np.array([float(v) for v in origin.get("rpy", "0 0 0").split()])
    axis_el = joint.find("axis")
    axis = np.array([float(v) for v in (axis_el.get("xyz") if axis_el is not None
                                        else "1 0 0").split()])
    axis = axis / np.linalg.norm(axis)
    R = Rotation.from_euler("xyz", rpy)  # URDF rpy: fixed-axis roll, pitch, yaw
    if kind == "prismatic":
        xyz = xyz + R.apply(axis * value)
    else:
        R = R * Rotation.from_rotvec(axis * value)
    origin.set("xyz", " ".join(repr(float(v)) for v in xyz))
    origin.set("rpy", " ".join(repr(float(v)) for v in R.as_euler("xyz")))
