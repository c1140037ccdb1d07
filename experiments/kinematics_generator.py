"""A second kinematic log generator, written apart from ``diegocal.sim`` (it imports none of it).

Why: ``diagnose --domain kinematics`` was tuned on the project's simulator; a generator with its
own code, trajectory, noise and the effects in their physical form tells whether a diagnosis
names real causes or the first simulator's habits (issue #31).

The robot: a URDF of ``example-robot-data`` (the iCub, 32 joints; the UR5) with a rotary pot on
every revolute joint and motion-capture markers on only some links (:func:`robot_dir`: a "blind"
robot, as a lab instruments one it bought). The hardware (true pot gains and biases, marker
positions a few cm from the nominal ones, the mocap frame, the effect's channel and parameters)
comes from ``hardware_seed``; a session (trajectory, noise, occlusions) from ``seed``.

Kinematics with Pinocchio directly. Each joint moves point to point by minimum-jerk (quintic)
segments between random targets in the inner 85 % of its range, 0.7-2.5 s each, with pauses;
the path is evaluated on a 1 kHz grid, so that a clock shift or a dead band acts on the
continuous motion rather than on the samples. Sensors at 100 Hz:

- pots: ``p = gain · m + bias`` of the motor-side angle m (the joint angle unless a gear has
  play), white noise (3 mV) and a 12-bit converter over 0-5 V (1.2 mV steps);
- markers: ``x = R (oMlink(q) d) + T`` in the mocap frame, noise white per axis (0.6, 0.6, 1.0
  mm: the depth axis of the cameras is worse) plus a slowly varying part (AR(1), 50 ms, 0.3 mm:
  the reconstruction's smoothing), occluded in runs (0-15 % of the samples per marker).

Effects, one per log, each in its physical form (``size`` drawn from :data:`SIZES` unless given):

- ``time_offset`` (s): the mocap samples the robot ``size`` late or early: marker sample k sees
  the joints at ``t_k + size`` (20-30 ms, either sign);
- ``backlash`` (rad): the gear between the joint's motor and its link has play: the link follows
  the motor through a dead band of ``size`` (a play operator on the 1 kHz path); the pot reads the
  motor side, the markers the link;
- ``sensor_nonlinearity`` (V): the pot is a resistive track whose wiper is loaded (a divider
  into a finite input resistance): ``V = Vs x / (1 + k x (1 − x))`` with x the wiper's place on
  the track, k the load ratio; k is set so that the reading departs from its best straight line
  over the session's motion by ``size`` at most;
- ``marker_slip`` (m): the marker's tape gives way at a time in 30-70 % of the first session and
  it slides by ``size`` over 0.2-0.5 s, then stays (later sessions see it moved);
- ``link_offset`` (m): a link of 10 cm or more is ``size`` longer or shorter than the URDF says
  (the joint's origin moved along the link, in its parent's frame: :meth:`Layout.link`).

Time: session ``index`` k starts at ``k · (duration + 60 s)``: sessions of one robot follow each
other on one clock, so a marker that slipped in the first stays moved in the next.

``/truth``: ``params`` in calib.yaml's layout-1 schema (``pots``, ``markers``, ``mocap``; the
pots' gain and bias of their linear part), ``effects`` ({cause, channel, region, values}), and the
noise-free signals ``q`` (link side, at the pots' times), ``pots`` and ``markers`` (without
occlusion), for judging only.
"""

from __future__ import annotations

import sysconfig
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pinocchio as pin
import yaml

from diegocal.io import Log, Truth, make_stream

SHARE = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix" / "share" / "example-robot-data" / "robots"
#: robot -> (URDF under SHARE, markers per chosen link)
ROBOTS = {
    "icub": ("icub_description/robots/icub.urdf", 1),
    "ur5": ("ur_description/urdf/ur5_joint_limited_robot.urdf", 3),
}
CAUSES = ("time_offset", "backlash", "sensor_nonlinearity", "marker_slip", "link_offset")
#: Ranges the size of each effect is drawn from (units: module docstring).
SIZES = {
    "time_offset": (0.020, 0.030),
    "backlash": (0.02, 0.05),
    "sensor_nonlinearity": (0.02, 0.05),
    "marker_slip": (0.01, 0.03),
    "link_offset": (0.005, 0.010),
}
RATE = 100.0
FINE = 1000.0  # Hz: the grid the motion is evaluated on
POT_NOISE = 0.003  # V
ADC_STEP = 5.0 / 4096  # V
MARKER_WHITE = np.array([0.0006, 0.0006, 0.0010])  # m per mocap axis
MARKER_SLOW = 0.0003  # m, AR(1) part
SLOW_TIME = 0.05  # s
GAP = 60.0  # s between sessions


def urdf(name: str) -> Path:
    return SHARE / ROBOTS[name][0]


# ----------------------------------------------------------------------------- the robot directory
def robot_dir(out: Path, name: str, seed: int = 3) -> Path:
    """Write ``out/<name>/`` (robot.urdf, sensors.yaml): a rotary pot on every revolute joint
    (gain U(0.8, 1.2) V/rad, bias near 2.5 V at the middle of the joint's range: the readings
    stay on a 0-5 V converter), markers
    on every other moving link along the joint order and the last (one per link on the iCub, three
    on the UR5), U(±5 cm) from the link's origin. Returns the directory."""
    rng = np.random.default_rng(seed)
    src = urdf(name)
    d = Path(out) / name
    d.mkdir(parents=True, exist_ok=True)
    (d / "robot.urdf").write_bytes(src.read_bytes())
    model = pin.buildModelFromUrdf(str(src))
    root = next(f.name for f in model.frames if f.type == pin.FrameType.BODY)
    joints = [model.names[j] for j in range(1, model.njoints) if model.joints[j].shortname().startswith("JointModelR")]
    pots = []
    for j in joints:
        k = model.getJointId(j) - 1
        lo, hi = model.lowerPositionLimit[k], model.upperPositionLimit[k]
        mid = 0.5 * (lo + hi) if np.isfinite(lo + hi) and hi - lo <= 2 * np.pi else 0.0
        gain = float(rng.uniform(0.8, 1.2))
        pots.append({"name": f"{j}_pot", "kind": "rotary", "joint": j, "gain": gain,
                     "bias": float(2.5 - gain * mid + rng.uniform(-0.2, 0.2))})
    child = {}
    for f in model.frames:
        if f.type == pin.FrameType.BODY and f.parentJoint > 0:
            child.setdefault(model.names[f.parentJoint], f.name)
    links = [child[j] for j in joints if j in child]
    chosen = links[1::2] + ([links[-1]] if links and links[-1] not in links[1::2] else [])
    per = ROBOTS[name][1]
    markers = [{"name": f"{link}_m{k}", "link": link, "xyz": [float(v) for v in rng.uniform(-0.05, 0.05, 3)]}
               for link in chosen for k in range(per)]
    sensors = {"urdf": "robot.urdf", "base_link": root, "pots": pots, "markers": markers}
    (d / "sensors.yaml").write_text(yaml.safe_dump(sensors, sort_keys=False))
    return d


@dataclass(frozen=True)
class Layout:
    """What sensors.yaml says, and the Pinocchio model of the URDF."""

    model: pin.Model
    pots: tuple  # (name, joint, gain, bias) nominal
    markers: tuple  # (name, link, xyz) nominal

    @classmethod
    def read(cls, directory: Path) -> Layout:
        s = yaml.safe_load((Path(directory) / "sensors.yaml").read_text())
        model = pin.buildModelFromUrdf(str(Path(directory) / s["urdf"]))
        pots = tuple((p["name"], p["joint"], float(p["gain"]), float(p["bias"])) for p in s["pots"])
        markers = tuple((m["name"], m["link"], np.asarray(m["xyz"], float)) for m in s["markers"])
        return cls(model, pots, markers)

    def joint_id(self, joint: str) -> int:
        return self.model.getJointId(joint)

    def moves_marker(self, joint: str) -> bool:
        """Whether the joint carries a marker (it is an ancestor of a marker's link)."""
        j0 = self.joint_id(joint)
        for _, link, _ in self.markers:
            j = self.model.frames[self.model.getFrameId(link)].parentJoint
            while j > 0:
                if j == j0:
                    return True
                j = self.model.parents[j]
        return False

    def channels(self, cause: str) -> list[str]:
        """Where an effect of ``cause`` may sit: pots whose joint carries a marker; links of 10 cm
        or more (:meth:`link`) after a moving joint, that carry a marker; any marker; the markers' clock."""
        if cause in ("backlash", "sensor_nonlinearity"):
            return [p for p, j, _, _ in self.pots if self.moves_marker(j)]
        if cause == "marker_slip":
            return [m for m, _, _ in self.markers]
        if cause == "link_offset":
            m = self.model
            return [m.names[j] for j in range(1, m.njoints)
                    if m.parents[j] > 0 and np.linalg.norm(self.link(m.names[j])) >= 0.1
                    and self.moves_marker(m.names[j])]
        return ["markers"]

    def link(self, joint: str) -> np.ndarray:
        """The link that ends at ``joint`` (3,), m, in its parent joint's frame: the joint's origin
        less its part along the joint's own axis (a shift along the axis is no longer link: markers
        that turn about that axis cannot tell it from their own positions)."""
        j = self.joint_id(joint)
        placement = self.model.jointPlacements[j]
        axis = placement.rotation @ _axis(self.model.joints[j])
        t = np.array(placement.translation)
        return t - (t @ axis) * axis


def _axis(joint) -> np.ndarray:
    """A revolute joint model's unit axis in its own frame."""
    fixed = {"JointModelRX": (1.0, 0.0, 0.0), "JointModelRY": (0.0, 1.0, 0.0), "JointModelRZ": (0.0, 0.0, 1.0)}
    a = np.array(fixed.get(joint.shortname()) or joint.extract().axis, float)
    return a / np.linalg.norm(a)


# ----------------------------------------------------------------------------- sessions
@dataclass(frozen=True)
class Session:
    """One log: the robot directory, duration (s), ``cause`` of the hidden effect (None: clean) on
    ``channel`` (None: drawn) with ``size`` (None: drawn), ``seed`` (motion, noise, occlusion),
    ``hardware_seed`` (the robot's true sensors and the effect), ``index`` (its place on the
    robot's clock: module docstring)."""

    robot: Path
    duration: float = 60.0
    cause: str | None = None
    channel: str | None = None
    size: float | None = None
    seed: int = 0
    hardware_seed: int = 0
    index: int = 0

    def next(self, k: int = 1) -> Session:
        """The same robot's session k later (another motion and noise)."""
        return replace(self, seed=self.seed + 7919 * k, index=self.index + k)

    def clean(self) -> Session:
        return replace(self, cause=None)


@dataclass(frozen=True)
class Hardware:
    gain: np.ndarray  # (P,) V/rad
    bias: np.ndarray  # (P,) V
    xyz: np.ndarray  # (M, 3) m
    R: np.ndarray
    T: np.ndarray
    effect: dict | None  # cause, channel, size, and its own parameters


def hardware(layout: Layout, session: Session) -> Hardware:
    """The robot's true sensors and the effect (from ``hardware_seed`` alone: every session of a
    robot shares them)."""
    rng = np.random.default_rng([session.hardware_seed, 17])
    P, M = len(layout.pots), len(layout.markers)
    g0 = np.array([p[2] for p in layout.pots])
    gain = g0 * (1 + rng.uniform(-0.1, 0.1, P))
    bias = np.array([p[3] for p in layout.pots]) + rng.uniform(-0.15, 0.15, P)
    direction = rng.normal(size=(M, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    xyz = np.array([m[2] for m in layout.markers]) + direction * rng.uniform(0.01, 0.03, (M, 1))
    R = _random_rotation(rng)
    T = rng.uniform([-1.0, -1.0, 0.8], [1.0, 1.0, 1.6])
    effect = None
    if session.cause is not None:
        erng = np.random.default_rng([session.hardware_seed, 29, CAUSES.index(session.cause)])
        choices = layout.channels(session.cause)
        channel = session.channel or choices[int(erng.integers(len(choices)))]
        lo, hi = SIZES[session.cause]
        size = float(erng.uniform(lo, hi)) if session.size is None else float(session.size)
        effect = {"cause": session.cause, "channel": channel, "size": size,
                  "sign": float(erng.choice([-1.0, 1.0])), "u": erng.uniform(size=4), "dir": erng.normal(size=3)}
    return Hardware(gain, bias, xyz, R, T, effect)


def _random_rotation(rng) -> np.ndarray:
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    return pin.Quaternion(q[0], q[1], q[2], q[3]).toRotationMatrix()


def minimum_jerk(lower, upper, t_end: float, rng) -> tuple[np.ndarray, np.ndarray]:
    """Joint paths on the grid ``(0, 1/FINE, ..., t_end)``: (N,) times, (N, n) angles. Each joint
    moves by minimum-jerk segments (x0 + (x1 − x0)(10s³ − 15s⁴ + 6s⁵)) between uniform targets in
    the inner 85 % of its range, 0.7-2.5 s each, a third of them followed by a pause of 0.2-1 s."""
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    t = np.arange(int(np.ceil(t_end * FINE)) + 1) / FINE
    out = np.empty((t.size, lower.size))
    for j in range(lower.size):
        lo, hi = lower[j] + 0.075 * (upper[j] - lower[j]), upper[j] - 0.075 * (upper[j] - lower[j])
        x0, s0 = rng.uniform(lo, hi), -rng.uniform(0, 1.0)
        knots, values = [s0], [x0]
        while knots[-1] < t_end:
            dur = rng.uniform(0.7, 2.5)
            knots.append(knots[-1] + dur)
            values.append(rng.uniform(lo, hi))
            if rng.random() < 1 / 3:
                knots.append(knots[-1] + rng.uniform(0.2, 1.0))
                values.append(values[-1])
        knots, values = np.array(knots), np.array(values)
        k = np.clip(np.searchsorted(knots, t, side="right") - 1, 0, knots.size - 2)
        s = (t - knots[k]) / (knots[k + 1] - knots[k])
        out[:, j] = values[k] + (values[k + 1] - values[k]) * (10 * s**3 - 15 * s**4 + 6 * s**5)
    return t, out


def play(x: np.ndarray, width: float) -> np.ndarray:
    """The link side (N,) of a gear with play ``width`` driven by the motor side x (N,): it stays
    put until the motor reaches an end of the dead band, then is dragged along; starts centred."""
    out = np.empty_like(x)
    h, y = 0.5 * width, float(x[0])
    for i, v in enumerate(x.tolist()):
        y = min(max(y, v - h), v + h)
        out[i] = y
    return out


def loaded_pot(x: np.ndarray, k: float) -> np.ndarray:
    """A loaded divider's output fraction for wiper places x in [0, 1]."""
    return x / (1.0 + k * x * (1.0 - x))


def _load_ratio(x: np.ndarray, departure: float, scale: float) -> float:
    """The load ratio k whose curve departs from its best line over the wiper places x (N,) by
    ``departure`` (V) at most, for a track of ``scale`` V (bisection: the departure grows with k)."""
    A = np.column_stack([x, np.ones_like(x)])

    def dev(k):
        y = scale * loaded_pot(x, k)
        return float(np.max(np.abs(y - A @ np.linalg.lstsq(A, y, rcond=None)[0])))

    lo, hi = 0.0, 1.0
    while dev(hi) < departure and hi < 1e3:
        hi *= 2
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if dev(mid) < departure else (lo, mid)
    return 0.5 * (lo + hi)


class Kinematics:
    """Marker positions in the base frame from joint angles (Pinocchio, one frame at a time)."""

    def __init__(self, model: pin.Model, links):
        self.model, self.data = model, model.createData()
        self.fids = [model.getFrameId(link) for link in links]

    def points(self, q: np.ndarray, xyz: np.ndarray) -> np.ndarray:
        """(T, M, 3): marker m at ``xyz[t, m]`` (T, M, 3) of its link, for angles q (T, n)."""
        out = np.empty(xyz.shape)
        for t in range(q.shape[0]):
            pin.framesForwardKinematics(self.model, self.data, q[t])
            for m, f in enumerate(self.fids):
                o = self.data.oMf[f]
                out[t, m] = o.rotation @ xyz[t, m] + o.translation
        return out


def generate(session: Session) -> Log:
    """One log of ``session`` (module docstring)."""
    layout = Layout.read(session.robot)
    hw = hardware(layout, session)
    eff = hw.effect or {}
    cause = eff.get("cause")
    rng = np.random.default_rng([session.seed, session.index, 5])
    model = layout.model
    T = int(round(session.duration * RATE))
    t0 = session.index * (session.duration + GAP)
    time = t0 + np.arange(T) / RATE
    lower, upper = model.lowerPositionLimit.copy(), model.upperPositionLimit.copy()
    wide = ~np.isfinite(lower) | ~np.isfinite(upper) | (upper - lower > 2 * np.pi)
    lower[wide], upper[wide] = -np.pi, np.pi
    pad = 0.2
    grid, motor = minimum_jerk(lower, upper, session.duration + 2 * pad, rng)
    grid = grid + t0 - pad
    link = motor.copy()
    pot_joint = [model.getJointId(j) - 1 for _, j, _, _ in layout.pots]
    names = [p[0] for p in layout.pots]
    if cause == "backlash":
        k = pot_joint[names.index(eff["channel"])]
        link[:, k] = play(motor[:, k], eff["size"])

    def at(x, times):  # the 1 kHz path read at ``times`` (linear interpolation)
        return np.stack([np.interp(times, grid, x[:, j]) for j in range(x.shape[1])], axis=1)

    q_pots, m_pots = at(link, time), at(motor, time)
    shift = eff["sign"] * eff["size"] if cause == "time_offset" else 0.0
    q_mocap = at(link, time + shift)

    # pots (the motor side)
    angle = m_pots[:, pot_joint]
    p_clean = hw.gain * angle + hw.bias
    values: dict = {}
    if cause == "sensor_nonlinearity":
        i = names.index(eff["channel"])
        j = pot_joint[i]
        travel = 1.15 * (upper[j] - lower[j]) * (1 + 0.2 * eff["u"][0])
        centre = 0.5 * (lower[j] + upper[j]) + 0.1 * (eff["u"][1] - 0.5) * (upper[j] - lower[j])
        scale = hw.gain[i] * travel  # V over the track
        x_session = 0.5 + (angle[:, i] - centre) / travel
        # the load ratio from the joint's range (hardware: the same in every session)
        inner = np.linspace(lower[j], upper[j], 201)
        kk = _load_ratio(0.5 + (inner - centre) / travel, eff["size"], scale)
        p_clean[:, i] = hw.bias[i] + scale * (loaded_pot(x_session, kk) - 0.5) + hw.gain[i] * centre
        values = {"form": "V = Vs x / (1 + k x (1 - x))", "load_ratio": kk, "travel_rad": travel,
                  "centre_rad": centre, "departure": eff["size"]}
    pots = p_clean + rng.normal(0.0, POT_NOISE, p_clean.shape)
    pots = np.round(pots / ADC_STEP) * ADC_STEP

    # markers
    geometry = model
    if cause == "link_offset":
        geometry = model.copy()
        j = model.getJointId(eff["channel"])
        along = layout.link(eff["channel"])
        delta = eff["sign"] * eff["size"] * along / np.linalg.norm(along)
        geometry.jointPlacements[j].translation = geometry.jointPlacements[j].translation + delta
        values = {"dxyz": delta.tolist(), "frame": "joint origin, in the parent joint frame",
                  "length_change": eff["sign"] * eff["size"]}
    M = len(layout.markers)
    xyz = np.broadcast_to(hw.xyz, (T, M, 3)).copy()
    region = None
    if cause == "marker_slip":
        m = [n for n, _, _ in layout.markers].index(eff["channel"])
        d = eff["dir"] / np.linalg.norm(eff["dir"]) * eff["size"]
        first = session.duration  # slips in the first session (index 0), on the robot's clock
        t_slip = (0.3 + 0.4 * eff["u"][2]) * first
        tau = 0.2 + 0.3 * eff["u"][3]
        s = np.clip((time + shift - t_slip) / tau, 0.0, 1.0)
        xyz[:, m] += (3 * s**2 - 2 * s**3)[:, None] * d
        values = {"time": t_slip, "transition_s": tau, "dxyz": d.tolist()}
        region = {"variable": "time", "low": float(t_slip), "high": None}
    if cause == "time_offset":
        values = {"seconds": shift, "convention": "markers[t] observe q(t + seconds)"}
    if cause == "backlash":
        i = names.index(eff["channel"])
        values = {"width": eff["size"], "width_reading": abs(hw.gain[i]) * eff["size"],
                  "side": "the pot reads the motor, the markers the link"}
    kin = Kinematics(geometry, [link_ for _, link_, _ in layout.markers])
    xb = kin.points(q_mocap, xyz)
    x_clean = xb @ hw.R.T + hw.T
    white = rng.normal(size=x_clean.shape) * MARKER_WHITE
    a = np.exp(-1.0 / (SLOW_TIME * RATE))
    e = rng.normal(size=x_clean.shape) * MARKER_SLOW * np.sqrt(1 - a * a)
    slow = np.empty_like(e)
    slow[0] = rng.normal(size=e.shape[1:]) * MARKER_SLOW
    for t in range(1, T):
        slow[t] = a * slow[t - 1] + e[t]
    x = x_clean + white + slow
    hidden = occlusion(T, M, rng)
    x[hidden] = np.nan

    truth_params = {
        "method": "truth",
        "pots": {n: {"gain": float(hw.gain[i]), "bias": float(hw.bias[i])} for i, n in enumerate(names)},
        "markers": {n: {"link": lk, "xyz": hw.xyz[i].tolist()} for i, (n, lk, _) in enumerate(layout.markers)},
        "mocap": {"R": hw.R.tolist(), "T": hw.T.tolist()},
        "sigma": {"pots": POT_NOISE, "markers": float(np.sqrt(np.mean(MARKER_WHITE**2) + MARKER_SLOW**2))},
    }
    values = {k: (v if isinstance(v, (str, list)) else float(v)) for k, v in values.items()}
    effects = [] if cause is None else [{"cause": cause, "channel": eff["channel"], "region": region,
                                         "values": {**values, "size": eff["size"]}}]
    joint_names = [model.names[j] for j in range(1, model.njoints)]
    signals = {
        "q": make_stream(joint_names, q_pots),
        "pots": make_stream(names, p_clean),
        "markers": make_stream([n for n, _, _ in layout.markers], x_clean),
    }
    return Log(
        time=time,
        streams={"pots": make_stream(names, pots), "markers": make_stream([n for n, _, _ in layout.markers], x)},
        robot=str(Path(session.robot).resolve()),
        rate_hz=RATE,
        truth=Truth(params=truth_params, effects=effects, signals=signals),
    )


def occlusion(T: int, M: int, rng) -> np.ndarray:
    """(T, M) bool: each marker hidden in runs of mean 0.4 s, 0-15 % of its samples."""
    out = np.zeros((T, M), bool)
    for m in range(M):
        frac = rng.uniform(0.0, 0.15)
        if frac <= 0:
            continue
        t = 0
        while t < T:
            t += int(rng.exponential(0.4 * RATE * (1 - frac) / frac)) + 1
            n = int(rng.exponential(0.4 * RATE)) + 1
            out[t : t + n, m] = True
            t += n
    return out
