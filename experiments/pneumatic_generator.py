"""A second pneumatic log generator, written apart from ``diegocal.sim`` (it imports none of it).

Why: ``diagnose`` was tuned on the project's own simulator; a generator with the same physics but
its own code, integrator, sensor, command and fault shapes tells whether a diagnosis names real
causes or the first simulator's habits (issue #31).

Physics, SI inside (Pa absolute, m², m³, kg/s), kPa in the log:

- thin-plate orifice flow, thesis eq. (4.1): ``m = C_d a p_u Ψ(p_d/p_u) / sqrt(R T)`` with Ψ
  constant below the critical ratio (choked) and ``sqrt(2κ/(κ-1) (x^(2/κ) - x^((κ+1)/κ)))`` above
  it; within 0.5 % of equal pressures Ψ is continued linearly to 0 (laminar end: eq. 4.1's slope is
  infinite there);
- the valve, eq. (4.2-4.3): a supply port and a room port whose areas open with the command,
  ``a_c = L_c + B w softplus((u - U_c)/w)``, ``a_r = L_r + B w softplus((U_r - u)/w)`` (softplus,
  not the thesis's smooth max: a second shape of the same physics);
- the chamber, eq. (4.4): ``ṗ = κ R T / V (ṁ_in - ṁ_out) - κ p V̇ / V`` with the volume of a
  cylinder whose piston follows the joint (sensors.yaml's ``bore_area``, ``stroke``,
  ``moment_arm``, ``dead_volume``, ``side``). The mechanics is not simulated (thesis §4.2: given
  V and V̇ the pressure does not depend on it): the joints follow smooth random paths.

Integration: a two-stage L-stable Rosenbrock method (ROS2, Verwer et al. 1999) at ``substeps``
per 10 ms tick (2 kHz), on the state (chamber pressure, supply-hose pressure) of every chamber of
every log generated together. Sensors as in thesis §4.5: pressure and pots are sampled at the
end of every sub-step and averaged over each tick (sample k holds the mean over the tick that
ends at its time), with white noise of the averaged reading. The valve command of sample k is
held over the tick that starts at it.

Effects, each in its physical form (``Effect``; sizes drawn by :func:`draw_effect` from the
ranges of :data:`SIZES`):

- ``valve_delay`` (s): the valve sees the command ``size`` late (rounded to the sub-step);
- ``chamber_leak`` (m²): an orifice of that area from the chamber to the room, thin-plate flow;
- ``supply_droop`` (m²): the chamber's valve draws from a hose of ``HOSE_VOLUME`` fed through a
  supply-line orifice of that area (a kinked tube, a clogged filter); the hose pressure sags
  while the valve draws, and recovers when it stops (without the effect the line is ideal);
- ``pressure_offset`` (kPa): the pressure sensor reads ``size`` high (low when negative);
- ``valve_play`` (V), outside ``diagnose``'s vocabulary (:data:`OTHER_CAUSES`): the valve's spool
  has ``size`` of play (as a gear's backlash, :func:`play`): it follows the command ``size / 2``
  behind and, on a reversal, holds until the command has come back the whole ``size``.

The robot's valves are hardware: drawn from ``hardware_seed``, the same in every session; the
session (paths, commands, noise, the effect's chamber and size when drawn) from ``seed``. The
effects never change what the session draws, so a log and its clean twin (the same seed
without effects) differ by the effect alone. ``/truth`` holds the valves, the effects with
their realised sizes (the sag they cause, for a droop) and the noise-free signals ``pressure``
(true chamber pressure, tick-averaged) and ``reading`` (what a noise-free sensor reads).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import yaml
from scipy.interpolate import CubicSpline

from diegocal.io import Log, Truth, make_stream

ROBOT_DIR = Path(__file__).resolve().parent / "pneumatic_robot"
KPA = 1e3
# Air (thesis Table 4.2): specific gas constant R/M, temperature, heat capacity ratio, discharge.
R_AIR = 8.314 / 0.029  # J/(kg K)
TEMPERATURE = 295.0  # K
KAPPA = 1.4
C_D = 0.72
X_CRIT = (2.0 / (KAPPA + 1.0)) ** (KAPPA / (KAPPA - 1.0))  # p_d/p_u below which the flow is choked
X_LAMINAR = 0.995  # p_d/p_u above which Ψ is continued linearly to 0
HOSE_VOLUME = 1.0e-5  # m³, the supply hose a restricted line feeds (half a metre of 5 mm tube)
GAMMA = 1.0 + 1.0 / np.sqrt(2.0)  # ROS2's γ
CAUSES = ("valve_delay", "chamber_leak", "supply_droop", "pressure_offset")
#: Effects the generator makes that no cause of ``diagnose`` names (experiments/pneumatic_oov.py).
OTHER_CAUSES = ("valve_play",)
#: The ranges effect sizes are drawn from, in each cause's unit (module docstring).
SIZES = {
    "valve_delay": (0.040, 0.050),  # s
    "chamber_leak": (0.35e-6, 0.8e-6),  # m², a hole of 0.67-1.0 mm
    "supply_droop": (0.8e-6, 1.6e-6),  # m², the supply line's orifice (a 1.0-1.4 mm hole)
    "pressure_offset": (9.0, 13.0),  # kPa, either sign
}


@dataclass(frozen=True)
class Effect:
    """One fault: ``cause`` (one of :data:`CAUSES`) on ``chamber`` with ``size`` in its unit."""

    cause: str
    chamber: str
    size: float


@dataclass(frozen=True)
class GeneratorOptions:
    """Options of :func:`generate`.

    duration : s;  rate_hz : sample (tick) rate;  substeps : integration steps per tick
    pressure_noise : std of the averaged pressure reading, kPa;  pot_noise : of a pot reading, V
    effects : :class:`Effect` tuple;  seed : the session;  hardware_seed : the robot's valves
    """

    duration: float = 60.0
    rate_hz: float = 100.0
    substeps: int = 20
    pressure_noise: float = 0.4
    pot_noise: float = 2e-4
    effects: tuple = ()
    seed: int = 0
    hardware_seed: int = 7


@dataclass(frozen=True)
class Chambers:
    """The robot's chambers (sensors.yaml), arrays (C,) in SI; ``pots`` name -> (joint, gain, bias)."""

    names: tuple
    joint: np.ndarray
    side: np.ndarray
    bore: np.ndarray
    stroke: np.ndarray
    arm: np.ndarray
    dead: np.ndarray
    supply: np.ndarray  # Pa
    room: np.ndarray  # Pa
    joints: tuple
    lower: np.ndarray
    upper: np.ndarray
    pots: dict = field(default_factory=dict)
    robot: str = ""  # the robot directory (the log's ``robot`` attribute)

    def volume(self, q, qd):
        """Chamber volume (m³) and its rate (m³/s), (..., C), from joint angles and rates (..., J)."""
        mid = 0.5 * (self.lower + self.upper)[self.joint]
        x = 0.5 * self.stroke + self.side * self.arm * (q[..., self.joint] - mid)
        return self.dead + self.bore * x, self.side * self.bore * self.arm * qd[..., self.joint]


def load_chambers(robot_dir=ROBOT_DIR) -> Chambers:
    """The chambers, pots and joint limits of a robot directory (read here, not by diegocal.robot)."""
    robot_dir = Path(robot_dir)
    spec = yaml.safe_load((robot_dir / "sensors.yaml").read_text())
    root = ET.parse(robot_dir / spec.get("urdf", "robot.urdf")).getroot()
    limits = {}
    for j in root.iter("joint"):
        lim = j.find("limit")
        if lim is not None:
            limits[j.get("name")] = (float(lim.get("lower")), float(lim.get("upper")))
    joints = tuple(limits)
    ch = spec["chambers"]
    col = lambda key: np.array([float(c[key]) for c in ch])  # noqa: E731
    for c in ch:
        stroke_used = float(c["moment_arm"]) * np.ptp(limits[c["joint"]])
        if stroke_used > float(c["stroke"]):
            raise ValueError(
                f"chamber {c['name']}: the joint's range needs {stroke_used:.4g} m of a {c['stroke']} m stroke"
            )
    pots = {p["name"]: (joints.index(p["joint"]), float(p["gain"]), float(p["bias"])) for p in spec["pots"]}
    return Chambers(
        tuple(c["name"] for c in ch),
        np.array([joints.index(c["joint"]) for c in ch]),
        col("side"),
        col("bore_area"),
        col("stroke"),
        col("moment_arm"),
        col("dead_volume"),
        col("supply") * KPA,
        col("room") * KPA,
        joints,
        np.array([limits[j][0] for j in joints]),
        np.array([limits[j][1] for j in joints]),
        pots,
        str(robot_dir),
    )


@dataclass(frozen=True)
class Valves:
    """Valve constants, arrays (C,): sealing voltages U_c, U_r (V), leakage areas L_c, L_r (m²),
    area per volt B (m²/V), softplus width w (V)."""

    U_c: np.ndarray
    U_r: np.ndarray
    L_c: np.ndarray
    L_r: np.ndarray
    B: np.ndarray
    w: np.ndarray

    def areas(self, u):
        """Supply- and room-port areas (m²) for commands ``u`` (..., C), V."""
        a_c = self.L_c + self.B * self.w * np.logaddexp(0.0, (u - self.U_c) / self.w)
        a_r = self.L_r + self.B * self.w * np.logaddexp(0.0, (self.U_r - u) / self.w)
        return a_c, a_r

    def to_dict(self, i: int) -> dict:
        return {k: float(getattr(self, k)[i]) for k in ("U_c", "U_r", "L_c", "L_r", "B", "w")}


def hardware(n: int, seed: int) -> Valves:
    """The valves of a robot with ``n`` chambers (centres near 5 V; a sealed band or an overlap)."""
    rng = np.random.default_rng([seed, 0xA1])
    centre = rng.normal(5.0, 0.2, n)
    band = rng.uniform(-0.1, 0.25, n)
    return Valves(
        centre + band / 2,
        centre - band / 2,
        rng.uniform(0.02e-6, 0.1e-6, n),
        rng.uniform(0.02e-6, 0.1e-6, n),
        rng.uniform(1.8e-6, 3.2e-6, n),
        rng.uniform(0.05, 0.12, n),
    )


def draw_effect(cause: str, chambers, rng: np.random.Generator, chamber: str | None = None) -> Effect:
    """An effect of ``cause`` on ``chamber`` (default: drawn) with a size drawn from :data:`SIZES`."""
    if cause not in SIZES:
        raise ValueError(f"unknown effect {cause!r} (expected one of {', '.join(CAUSES)})")
    name = chamber or str(chambers[int(rng.integers(len(chambers)))])
    lo, hi = SIZES[cause]
    size = float(rng.uniform(lo, hi))
    if cause == "pressure_offset":
        size *= float(rng.choice([-1.0, 1.0]))
    return Effect(cause, name, size)


# ----------------------------------------------------------------------------- thin-plate flow
def _psi(x):
    """Ψ(x) of eq. (4.1) and dΨ/dx, x = p_d/p_u in [0, 1] (choked, subsonic, laminar end)."""
    k = KAPPA
    e1, e2, c = 2.0 / k, (k + 1.0) / k, 2.0 * k / (k - 1.0)
    xs = np.clip(x, X_CRIT, X_LAMINAR)
    w = np.sqrt(c * (xs**e1 - xs**e2))
    dw = c * (e1 * xs ** (e1 - 1.0) - e2 * xs ** (e2 - 1.0)) / (2.0 * w)
    w_lam = np.sqrt(c * (X_LAMINAR**e1 - X_LAMINAR**e2))
    lam = x > X_LAMINAR
    psi = np.where(lam, w_lam * (1.0 - x) / (1.0 - X_LAMINAR), w)
    dpsi = np.where(lam, -w_lam / (1.0 - X_LAMINAR), np.where(x < X_CRIT, 0.0, dw))
    return psi, dpsi


def flow(p1, p2, area):
    """Mass flow (kg/s) through an orifice of ``area`` (m²) from p1 to p2 (Pa; negative when p2 >
    p1) and its derivatives in p1 and p2 (kg/(s Pa))."""
    fwd = p1 >= p2
    pu, pd = np.where(fwd, p1, p2), np.where(fwd, p2, p1)
    pu = np.maximum(pu, 1.0)
    x = np.minimum(pd / pu, 1.0)
    psi, dpsi = _psi(x)
    k = C_D * area / np.sqrt(R_AIR * TEMPERATURE)
    m = k * pu * psi
    d_up, d_down = k * (psi - x * dpsi), k * dpsi
    sign = np.where(fwd, 1.0, -1.0)
    return sign * m, np.where(fwd, d_up, -d_down), np.where(fwd, d_down, -d_up)


# ----------------------------------------------------------------------------- session inputs
def _joint_paths(ch: Chambers, duration: float, rng: np.random.Generator):
    """Smooth random joint paths: cubic splines through knots every 0.15-0.8 s inside 90 % of each
    joint's range. Returns q(t), qd(t) callables ((N,) -> (N, J))."""
    n_j = len(ch.joints)
    splines = []
    for j in range(n_j):
        gaps = rng.uniform(0.15, 0.8, int(duration / 0.15) + 4)
        knots = np.concatenate([[-1.0], -1.0 + np.cumsum(gaps)])
        knots = knots[knots < duration + 1.0]
        mid, half = 0.5 * (ch.lower[j] + ch.upper[j]), 0.45 * (ch.upper[j] - ch.lower[j])
        values = mid + half * np.clip(rng.normal(0.0, 0.6, knots.size), -1.0, 1.0)
        splines.append(CubicSpline(knots, values, bc_type="natural"))
    lo, hi = ch.lower + 0.02 * (ch.upper - ch.lower), ch.upper - 0.02 * (ch.upper - ch.lower)

    def q(t):
        return np.clip(np.stack([s(t) for s in splines], axis=-1), lo, hi)

    def qd(t):
        inside = (q(t) > lo) & (q(t) < hi)
        return np.stack([s(t, 1) for s in splines], axis=-1) * inside

    return q, qd


def _levels(rng, n_ticks: int, mean_hold: float, std: float, ramps: bool = False) -> np.ndarray:
    """(n_ticks,) random levels N(0, std²) held for exponential durations (mean ``mean_hold``
    ticks); with ``ramps``, half of the changes are linear sweeps over the hold instead of steps."""
    out = np.empty(n_ticks)
    t, level = 0, 0.0
    while t < n_ticks:
        hold = max(1, int(rng.exponential(mean_hold)))
        new = rng.normal(0.0, std)
        seg = np.full(min(hold, n_ticks - t), new)
        if ramps and rng.random() < 0.5:
            seg = level + (new - level) * (np.arange(1, seg.size + 1) / hold)
        out[t : t + seg.size] = seg
        t, level = t + hold, new
    return out


def _commands(ch: Chambers, n_ticks: int, rng: np.random.Generator) -> np.ndarray:
    """(n_ticks, C) valve commands in (3, 7) V: an antagonistic drive and a co-contraction per joint
    plus each valve's own steps, squashed by 5 + 2 tanh(0.4 z)."""
    z = np.zeros((n_ticks, len(ch.names)))
    for j in range(len(ch.joints)):
        sel = ch.joint == j
        drive = _levels(rng, n_ticks, 30, 1.3, ramps=True)
        co = _levels(rng, n_ticks, 120, 0.6)
        z[:, sel] += drive[:, None] * ch.side[sel] + co[:, None]
    for i in range(len(ch.names)):
        z[:, i] += _levels(rng, n_ticks, 15, 0.7)
    return 5.0 + 2.0 * np.tanh(0.4 * z)


def play(u: np.ndarray, width: float) -> np.ndarray:
    """The command (T,) a spool with play ``width`` follows: it moves only when ``u`` pushes it
    from more than ``width / 2`` away (a backlash operator)."""
    out = np.empty_like(u)
    y = float(u[0])
    for k, x in enumerate(u):
        y = min(max(y, x - 0.5 * width), x + 0.5 * width)
        out[k] = y
    return out


# ----------------------------------------------------------------------------- integration
@dataclass
class _Batch:
    """Every chamber of every log generated together, as flat columns (B,)."""

    supply: np.ndarray
    room: np.ndarray
    leak: np.ndarray  # m²
    line: np.ndarray  # m², 0 = ideal line (no hose state)
    delay_sub: np.ndarray  # int, sub-steps
    valves: Valves

    def rhs(self, p, m, a_c, a_r, vol, vol_rate):
        """ṗ, ṁ_hose (Pa/s) and their 2x2 Jacobian, eq. (4.4); the hose is isothermal."""
        hose = self.line > 0
        m = np.where(hose, m, self.supply)
        # the three orifices (supply port, exhaust with the leak, supply line) in one call: per
        # element the same arithmetic, a third of the calls
        up = np.concatenate([m, p, self.supply])
        down = np.concatenate([p, self.room, m])
        q, d_up, d_down = flow(up, down, np.concatenate([a_c, a_r + self.leak, self.line]))
        B = p.shape[0]
        q_c, q_r, q_s = q[:B], q[B : 2 * B], q[2 * B :]
        dqc_m, dqr_p = d_up[:B], d_up[B : 2 * B]
        dqc_p, dqs_m = d_down[:B], d_down[2 * B :]
        gain = KAPPA * R_AIR * TEMPERATURE / vol
        comp = KAPPA * vol_rate / vol
        fp = gain * (q_c - q_r) - comp * p
        jpp = gain * (dqc_p - dqr_p) - comp
        jpm = gain * dqc_m * hose
        h = np.where(hose, R_AIR * TEMPERATURE / HOSE_VOLUME, 0.0)
        fm = h * (q_s - q_c)
        jmm = h * (dqs_m - dqc_m)
        jmp = -h * dqc_p
        return fp, fm, jpp, jpm, jmp, jmm, q_c


def _ros2(batch: _Batch, p, m, a_c, a_r, vols, dt):
    """One ROS2 step of (p, m) over ``dt`` with the valve areas held; ``vols`` the volume and its
    rate at the step's start and end. Returns (p, m, supply-port flow at the start)."""
    (v0, vd0), (v1, vd1) = vols
    fp, fm, jpp, jpm, jmp, jmm, q_c = batch.rhs(p, m, a_c, a_r, v0, vd0)
    a, b, c, d = 1.0 - GAMMA * dt * jpp, -GAMMA * dt * jpm, -GAMMA * dt * jmp, 1.0 - GAMMA * dt * jmm
    det = a * d - b * c

    def solve(r1, r2):
        return (d * r1 - b * r2) / det, (a * r2 - c * r1) / det

    k1p, k1m = solve(fp, fm)
    fp2, fm2 = batch.rhs(p + dt * k1p, m + dt * k1m, a_c, a_r, v1, vd1)[:2]
    k2p, k2m = solve(fp2 - 2.0 * k1p, fm2 - 2.0 * k1m)
    p_new = np.maximum(p + dt * (1.5 * k1p + 0.5 * k2p), 1.0)
    m_new = np.maximum(m + dt * (1.5 * k1m + 0.5 * k2m), 1.0)
    return p_new, m_new, q_c


def _integrate(batch: _Batch, u, vol, vol_rate, n_sub: int, dt: float):
    """Tick averages (n_ticks + 1, B) of the pressure, of the hose pressure and of the supply-port
    flow; ``u`` (n_ticks, B) commands, ``vol``/``vol_rate`` (N + 1, B) at every sub-step end."""
    n_ticks, B = u.shape
    cols = np.arange(B)
    a_c_tick, a_r_tick = batch.valves.areas(u)
    p, m = batch.room.copy(), batch.supply.copy()
    out = np.empty((3, n_ticks + 1, B))
    out[0, 0], out[1, 0], out[2, 0] = p, m, 0.0
    for k in range(n_ticks):
        acc = np.zeros((3, B))
        for s in range(n_sub):
            j = k * n_sub + s
            tick = np.maximum(j - batch.delay_sub, 0) // n_sub  # the command the valve sees
            a_c, a_r = a_c_tick[tick, cols], a_r_tick[tick, cols]
            p, m, q_c = _ros2(batch, p, m, a_c, a_r, ((vol[j], vol_rate[j]), (vol[j + 1], vol_rate[j + 1])), dt)
            acc[0] += p
            acc[1] += np.where(batch.line > 0, m, batch.supply)
            acc[2] += q_c
        out[:, k + 1] = acc / n_sub
    return out


def generate(options: GeneratorOptions = GeneratorOptions(), robot_dir=ROBOT_DIR) -> Log:
    """One log of the robot in ``robot_dir`` (see the module docstring)."""
    return generate_many([options], robot_dir)[0]


def generate_many(options_list, robot_dir=ROBOT_DIR) -> list[Log]:
    """Logs for several options (same duration, rate and sub-steps), integrated together."""
    options_list = list(options_list)
    first = options_list[0]
    shared = (first.duration, first.rate_hz, first.substeps)
    if any((o.duration, o.rate_hz, o.substeps) != shared for o in options_list):
        raise ValueError("logs generated together share duration, rate_hz and substeps")
    ch = load_chambers(robot_dir)
    C, n_sub = len(ch.names), first.substeps
    n_ticks = int(round(first.duration * first.rate_hz))
    dt = 1.0 / (first.rate_hz * n_sub)
    t_sub = np.arange(n_ticks * n_sub + 1) * dt  # sub-step ends (and the start)
    sessions, cols = [], {k: [] for k in ("leak", "line", "delay", "U_c", "U_r", "L_c", "L_r", "B", "w")}
    u_all, vol_all, rate_all = [], [], []
    for o in options_list:
        rng = np.random.default_rng([o.seed, 0x5E55])
        q, qd = _joint_paths(ch, first.duration, rng)
        u = _commands(ch, n_ticks, rng)
        noise = np.random.default_rng([o.seed, 0x0015E])
        valves = hardware(C, o.hardware_seed)
        leak, line, delay = np.zeros(C), np.zeros(C), np.zeros(C, int)
        seen = u.copy()  # the command the valves see
        for e in o.effects:
            i = ch.names.index(e.chamber)
            if e.cause == "valve_delay":
                delay[i] = int(round(e.size / dt))
            elif e.cause == "chamber_leak":
                leak[i] += e.size
            elif e.cause == "supply_droop":
                line[i] = e.size
            elif e.cause == "valve_play":
                seen[:, i] = play(u[:, i], e.size)
            elif e.cause != "pressure_offset":
                raise ValueError(f"unknown effect {e.cause!r}")
        for k, v in (("leak", leak), ("line", line), ("delay", delay)):
            cols[k].append(v)
        for k in ("U_c", "U_r", "L_c", "L_r", "B", "w"):
            cols[k].append(getattr(valves, k))
        qs, qds = q(t_sub), qd(t_sub)
        vol, rate = ch.volume(qs, qds)
        u_all.append(seen)
        vol_all.append(vol)
        rate_all.append(rate)
        sessions.append((o, qs, u, noise, valves, delay))
    cat = lambda k: np.concatenate(cols[k])  # noqa: E731
    n_logs = len(options_list)
    batch = _Batch(
        np.tile(ch.supply, n_logs),
        np.tile(ch.room, n_logs),
        cat("leak"),
        cat("line"),
        cat("delay"),
        Valves(*(cat(k) for k in ("U_c", "U_r", "L_c", "L_r", "B", "w"))),
    )
    avg = _integrate(batch, np.hstack(u_all), np.hstack(vol_all), np.hstack(rate_all), n_sub, dt)
    return [_log(ch, o, qs, u, noise, valves, delay * dt, avg[:, :, i * C : (i + 1) * C], n_sub)
            for i, (o, qs, u, noise, valves, delay) in enumerate(sessions)]


def _log(ch: Chambers, o: GeneratorOptions, qs, u, noise, valves: Valves, delay, avg, n_sub: int) -> Log:
    """The diegocal log of one session from its tick averages (``avg``: pressure, hose, flow)."""
    n_ticks = u.shape[0]
    time = np.arange(n_ticks + 1) / o.rate_hz
    pressure = avg[0] / KPA
    offset = np.zeros(len(ch.names))
    for e in o.effects:
        if e.cause == "pressure_offset":
            offset[ch.names.index(e.chamber)] += e.size
    reading = pressure + offset
    measured = reading + noise.normal(0.0, o.pressure_noise, reading.shape)
    # pots: the joint angle at every sub-step end, averaged over each tick like the pressure
    q_avg = np.vstack([qs[:1], qs[1:].reshape(n_ticks, n_sub, -1).mean(axis=1)])
    names = tuple(ch.pots)
    pots = np.column_stack([g * q_avg[:, j] + b for j, g, b in (ch.pots[n] for n in names)])
    pots = pots + noise.normal(0.0, o.pot_noise, pots.shape)
    effects = []
    for e in o.effects:
        i = ch.names.index(e.chamber)
        values = {"size": e.size, "unit": {"valve_delay": "s", "chamber_leak": "m2", "supply_droop": "m2",
                                           "pressure_offset": "kPa", "valve_play": "V"}[e.cause]}
        if e.cause == "valve_delay":
            values["delay_s"] = float(delay[i])
        if e.cause == "supply_droop":
            sag = (ch.supply[i] - avg[1][:, i]) / KPA
            values.update(sag_max_kpa=float(sag.max()), sag_rms_kpa=float(np.sqrt(np.mean(sag**2))),
                          sag_p90_kpa=float(np.percentile(sag, 90)))
        effects.append({"cause": e.cause, "channel": e.chamber, "region": None, "values": values})
    truth = Truth(
        params={
            "model": "thin-plate (experiments.pneumatic_generator)",
            "gas": {"R_specific": R_AIR, "T": TEMPERATURE, "kappa": KAPPA, "C_d": C_D},
            "substeps": n_sub,
            "hardware_seed": o.hardware_seed,
            "valves": {n: valves.to_dict(i) for i, n in enumerate(ch.names)},
            "offsets": {n: float(offset[i]) for i, n in enumerate(ch.names)},
        },
        effects=effects,
        signals={
            "q": make_stream(ch.joints, q_avg),
            "pressure": make_stream(ch.names, pressure),
            "reading": make_stream(ch.names, reading),
        },
    )
    streams = {
        "pressure": make_stream(ch.names, measured),
        "valve": make_stream(ch.names, np.vstack([u, u[-1:]])),
        "pots": make_stream(names, pots),
    }
    return Log(time, streams, robot=ch.robot, rate_hz=o.rate_hz, truth=truth)


def inputs(options: GeneratorOptions = GeneratorOptions(), robot_dir=ROBOT_DIR) -> Log:
    """The session's commands and pot readings (noise-free) with the pressure held at room: the
    inputs of a log without its physics, for data made by a parametric model
    (``diegocal.pneumatic.synthetic``)."""
    ch = load_chambers(robot_dir)
    rng = np.random.default_rng([options.seed, 0x5E55])
    q, _ = _joint_paths(ch, options.duration, rng)
    n_ticks = int(round(options.duration * options.rate_hz))
    u = _commands(ch, n_ticks, rng)
    time = np.arange(n_ticks + 1) / options.rate_hz
    q_t = q(time)
    names = tuple(ch.pots)
    pots = np.column_stack([g * q_t[:, j] + b for j, g, b in (ch.pots[n] for n in names)])
    streams = {
        "pressure": make_stream(ch.names, np.tile(ch.room / KPA, (n_ticks + 1, 1))),
        "valve": make_stream(ch.names, np.vstack([u, u[-1:]])),
        "pots": make_stream(names, pots),
    }
    return Log(time, streams, robot=ch.robot, rate_hz=options.rate_hz)


def clean_twin(options: GeneratorOptions) -> GeneratorOptions:
    """The same session without its effects (the reference of an effect's own error)."""
    return replace(options, effects=())
