"""`simulate pneumatics`: valve-chamber logs from the thin-plate physics of thesis §4.2.

Physics (SI inside, kPa absolute in the log): port flow by the thin-plate function (4.1) with
Table 4.2's constants and (4.12-4.14); proportional valve areas with the smooth max (4.3); chamber
pressure dynamics (4.4) with volume and volume rate from the cylinder geometry and the joint
motion; two valves per cylinder, one per chamber (§4.2.1). Supply and room pressures come from
sensors.yaml (620 / 100 kPa for the bundled robots, Fig. 4.3).

Integration. Small chambers make (4.4) stiff (§4.3: µs time scales), so each 100 Hz control tick
is cut into ``substeps`` exponential-Rosenbrock (exponential Euler) steps,
p ← p + dt f(p) φ1(dt ∂f/∂p), φ1(z) = (eᶻ - 1)/z, which is exact for the linearised dynamics and
stable for any dt; the step is vectorised over all chambers. Tests check that halving dt moves the
sampled pressures by less than the sensor noise and that a Radau reference agrees.

Sensors as in §4.5: pressures and pots are sampled fast and averaged over each 10 ms tick (the
average of the sub-step trajectory, trapezoid rule) plus white noise of the averaged reading.

Mechanics are not simulated (§4.2, "Independence from the Mechanics": given v and v̇ the pressure
does not depend on them): the joints follow a violent band-limited random motion inside their
limits and the valve commands (3-7 V, §4.5) are random steps and sweeps that explore the whole
command range (§4.5.3: "explore the state-space as violently as possible"). So this is not the
thesis's PID-driven flailing: a sealed chamber can be compressed above the supply pressure,
which a real joint would resist; the motion is kept moderate (components up to 1.5 Hz) so that
this stays within a few kPa (an earlier, harsher motion reached 1000 kPa and the model, whose
s() lives between P_r and P_c, could not follow it). A variant with a
1-DoF mechanics per joint driven by its pistons under a PD controller was tried: the closed
loop makes trajectories sensitive to the step size (halving it moves samples by ~2 kPa RMS after
3 s, through the timing of joint-limit hits), and the 9-parameter model's 2-s drift rose to a
median of 5.5 % (max 12 %) of Pc - Pr; see the final report of this work.

Effects (``--effect NAME[:CHAMBER][=SIZE]``; SIZE in the unit given, default in brackets), each
with its own physical shape, independent of the model's terms that ``diagnose`` fits:

- ``valve_delay`` [0.03 s]: the spool follows the command SIZE seconds late (the held 10 ms command
  shifted in continuous time, to the sub-step);
- ``chamber_leak`` [1e-6 m², a hole of 1.1 mm]: an orifice of SIZE m² from the chamber to the
  room, with the thin-plate flow of eq. (4.1) (choked above the critical ratio). An orifice no
  larger than the valve's own room-port leakage (0.03-0.12e-6 m² here; the default was 0.08e-6)
  is, to any valve model, a slightly different valve, so the default is one that matters;
- ``supply_droop`` [100 kPa per g/s; 1 on the shared line]: the supply pressure a chamber sees
  drops by SIZE kPa per g/s of the mass flow drawn from the supply (its own flow, or, with the
  channel ``supply``, the whole robot's flow through one shared line), from the previous
  sub-step's flow; a filling chamber draws a few g/s, so the default sags its supply by
  ~100 kPa while it fills (the former 10 sagged it by ~2 kPa RMS, below the model's own error);
- ``pressure_offset`` [15 kPa]: the pressure sensor reads SIZE kPa high.

Chamber geometry keys (sensors.yaml ``chambers:``, all optional; defaults in brackets):
``side`` [+1 for *.flex, -1 otherwise], ``bore_area`` [2e-4 m²], ``stroke`` [0.04 m],
``moment_arm`` [0.9 stroke / joint range], ``dead_volume`` [2e-6 m³].
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass

import numpy as np

from diegocal.errors import RobotConfigError
from diegocal.io import Log, Truth, make_stream
from diegocal.robot import Robot, predict_pots
from diegocal.sim.effects import SimOptionError, check_channel, check_effects, effect_record
from diegocal.sim.thin_plate import GasConstants, ValveGeometry, z_flow

EXPERIMENTS = ("dynamic", "steady-state")
KPA = 1e3
SESSION_GAP_S = 1.0
U_LOW, U_HIGH = 3.0, 7.0  # §4.5: "we used 3 < u < 7 Volts"
DEFAULTS = {"bore_area": 2.0e-4, "stroke": 0.04, "dead_volume": 2.0e-6}
EFFECT_DEFAULTS = {
    "valve_delay": {"delay_s": 0.03},
    "chamber_leak": {"area_m2": 1e-6},
    "supply_droop": {"kpa_per_g_s": 100.0},
    "pressure_offset": {"offset": 15.0},
}
#: ``supply_droop:supply``: one supply line shared by every chamber (module docstring).
SHARED_LINE = "supply"
#: The value ``--effect NAME=SIZE`` sets, per effect (its unit: the module docstring).
EFFECT_SIZE = {"valve_delay": "delay_s", "chamber_leak": "area_m2", "supply_droop": "kpa_per_g_s",
               "pressure_offset": "offset"}


@dataclass(frozen=True)
class PneumaticSimOptions:
    """Options of the pneumatic simulator, parsed once.

    duration : s;  rate_hz : control / sample rate (100 Hz, §4.5)
    substeps : integration steps per tick
    experiment : "dynamic" (flailing, §4.5.3) or "steady-state" (locked cylinders, slow
        sweep, §4.5.2)
    pressure_noise : std of the averaged pressure reading, kPa;  pot_noise : std of a pot reading
    effects : effect requests (``diegocal.sim.effects``);  seed : seeds every random choice
    sessions : independent recordings of ``duration`` each, simulated together (vectorised) and
        written one after the other, separated by a gap of SESSION_GAP_S in time
    """

    duration: float = 60.0
    rate_hz: float = 100.0
    substeps: int = 20
    experiment: str = "dynamic"
    pressure_noise: float = 0.3
    pot_noise: float = 1e-4
    effects: tuple = ()
    seed: int = 0
    sessions: int = 1


@dataclass(frozen=True)
class Cylinders:
    """Per-chamber geometry, arrays (C,), SI: piston travel x = stroke/2 + side·arm·(q - mid)."""

    joint_index: np.ndarray
    side: np.ndarray
    bore_area: np.ndarray
    stroke: np.ndarray
    moment_arm: np.ndarray
    dead_volume: np.ndarray
    mid: np.ndarray

    def volume(self, q, qd):
        """Chamber volume (m³) and rate (m³/s), (..., C), from joint angles and rates (..., n)."""
        qc, qdc = q[..., self.joint_index], qd[..., self.joint_index]
        x = 0.5 * self.stroke + self.side * self.moment_arm * (qc - self.mid)
        inside = (x > 0) & (x < self.stroke)
        x = np.clip(x, 0.0, self.stroke)
        return self.dead_volume + self.bore_area * x, np.where(
            inside, self.side * self.bore_area * self.moment_arm * qdc, 0.0
        )


def cylinders(robot: Robot) -> Cylinders:
    """Geometry of every chamber from sensors.yaml, with the defaults of the module doc."""
    chambers = robot.sensors.chambers
    if not chambers:
        raise RobotConfigError(
            f"robot {robot.name!r} has no chambers in sensors.yaml; nothing to simulate"
        )
    cols = {
        k: []
        for k in ("joint_index", "side", "bore_area", "stroke", "moment_arm", "dead_volume", "mid")
    }
    for c in chambers:
        j = robot.joint_index(c.joint)
        lo, hi = robot.lower[j], robot.upper[j]
        rng_q = hi - lo if np.isfinite(hi - lo) and hi > lo else 2.0
        stroke = float(c.extra.get("stroke", DEFAULTS["stroke"]))
        cols["joint_index"].append(j)
        cols["side"].append(float(c.extra.get("side", 1.0 if c.name.endswith(".flex") else -1.0)))
        cols["bore_area"].append(float(c.extra.get("bore_area", DEFAULTS["bore_area"])))
        cols["stroke"].append(stroke)
        cols["moment_arm"].append(float(c.extra.get("moment_arm", 0.9 * stroke / rng_q)))
        cols["dead_volume"].append(float(c.extra.get("dead_volume", DEFAULTS["dead_volume"])))
        cols["mid"].append(0.5 * (lo + hi) if np.isfinite(hi - lo) else 0.0)
    out = {k: np.array(v, dtype=int if k == "joint_index" else float) for k, v in cols.items()}
    if (
        (out["bore_area"] <= 0).any()
        or (out["stroke"] <= 0).any()
        or (out["dead_volume"] <= 0).any()
    ):
        raise RobotConfigError(
            "sensors.yaml: chamber bore_area, stroke and dead_volume must be positive"
        )
    return Cylinders(**out)


def robot_valves(robot: Robot) -> ValveGeometry:
    """The valves of this robot: constants fixed by its chamber names (a property of the hardware,
    the same in every simulated session, whatever ``--seed``), drawn by :func:`random_valves`."""
    key = "|".join(robot.sensors.chamber_names).encode()
    return random_valves(len(robot.sensors.chambers), np.random.default_rng(zlib.crc32(key)))


def random_valves(n: int, rng: np.random.Generator) -> ValveGeometry:
    """Valve constants (eq. 4.3) that differ from chamber to chamber, like Fig. 4.6's styles."""
    centre = 5.0 + rng.normal(0.0, 0.15, n)
    gap = rng.uniform(-0.15, 0.3, n)  # U_c - U_r: > 0 sealed band, < 0 both ports partly open
    return ValveGeometry(
        U_c=centre + gap / 2,
        U_r=centre - gap / 2,
        L_c=rng.uniform(0.03, 0.12, n) * 1e-6,
        L_r=rng.uniform(0.03, 0.12, n) * 1e-6,
        B=rng.uniform(1.5, 3.0, n) * 1e-6,
        smooth=rng.uniform(0.8, 1.5, n) * 1e-6,
    )


def smooth_random(rng, t, n, f_lo=0.05, f_hi=2.5, k=8):
    """Band-limited random signals (sum of k sines, log-uniform frequencies) at times t (T,): (T, n)
    values with unit-ish std, and their time derivative."""
    f = np.exp(rng.uniform(np.log(f_lo), np.log(f_hi), (k, n)))
    a = rng.normal(0.0, 1.0, (k, n)) * np.sqrt(2.0 / k)
    ph = rng.uniform(0, 2 * np.pi, (k, n))
    arg = 2 * np.pi * f[None] * t[:, None, None] + ph[None]
    return np.einsum("tkn,kn->tn", np.sin(arg), a), np.einsum(
        "tkn,kn->tn", np.cos(arg), a * 2 * np.pi * f
    )


def random_steps(rng, n_ticks, n, mean_hold, std):
    """Piecewise-constant random levels (n_ticks, n), held for exponential durations (ticks)."""
    switch = rng.random((n_ticks, n)) < 1.0 / mean_hold
    levels = rng.normal(0.0, std, (n_ticks + 1, n))
    return levels[np.cumsum(switch, axis=0), np.arange(n)]


def simulate_pneumatics(robot: Robot, options: PneumaticSimOptions) -> Log:
    """Simulate every chamber of ``robot``; returns a log with pressure, valve, pots and /truth."""
    _check_options(options)
    rng = np.random.default_rng(options.seed)
    cyl = cylinders(robot)
    names = robot.sensors.chamber_names
    C, S = len(names), options.sessions
    valve = robot_valves(robot)
    gas = GasConstants()
    supply = np.array([c.supply for c in robot.sensors.chambers]) * KPA
    room = np.array([c.room for c in robot.sensors.chambers]) * KPA
    n_ticks = int(round(options.duration * options.rate_hz))
    dt_tick = 1.0 / options.rate_hz
    n_sub = options.substeps
    t_tick = np.arange(n_ticks + 1) * dt_tick
    q_fns = [_joint_motion(robot, cyl, options, rng) for _ in range(S)]
    # (n_ticks, S, C): the command held over each tick, per session
    u = np.stack([_valve_commands(options, cyl, n_ticks, rng) for _ in range(S)], axis=1)
    effects, delay, leak, droop, droop_shared, offset = _effects(options, names, rng)
    lag_sub = np.round(delay * options.rate_hz * options.substeps).astype(int)  # (C,) sub-steps
    # Sessions and chambers are independent: integrate them together as S*C flat columns.
    flat = lambda x: np.broadcast_to(x, (S, C)).ravel()  # noqa: E731
    supply_f, room_f, droop_f = flat(supply), flat(room), flat(droop)
    p = room_f.copy()
    p_avg = np.empty((n_ticks + 1, S * C))
    p_avg[0] = p
    m_supply = np.zeros(S * C)
    chunk = 250
    for t0 in range(0, n_ticks, chunk):
        t1 = min(t0 + chunk, n_ticks)
        ts = (
            t_tick[t0] + (np.arange((t1 - t0) * n_sub) + 0.5) * dt_tick / n_sub
        )  # sub-step midpoints
        q, qd = (np.stack(x, axis=1) for x in zip(*(fn(ts) for fn in q_fns), strict=True))
        vol, vol_rate = (x.reshape(t1 - t0, n_sub, S * C) for x in cyl.volume(q, qd))
        for i in range(t1 - t0):
            a_c, a_r = valve.areas(u[t0 + i])
            a_c, a_r = a_c.ravel(), (a_r + leak).ravel()
            acc = np.zeros(S * C)
            for k in range(n_sub):
                if lag_sub.any():  # the spool sees the command of lag_sub sub-steps ago
                    tick = np.maximum(((t0 + i) * n_sub + k - lag_sub) // n_sub, 0)
                    a_c, a_r = valve.areas(u[tick, :, np.arange(C)].T)
                    a_c, a_r = a_c.ravel(), (a_r + leak).ravel()
                # supply droop: kPa per g/s = 1e6 Pa per kg/s, on the session's total or own flow
                flow = np.repeat(m_supply.reshape(S, C).sum(1), C) if droop_shared else m_supply
                p, mean, m_supply = _substep(
                    p,
                    a_c,
                    a_r,
                    supply_f - droop_f * flow * 1e6,
                    room_f,
                    vol[i, k],
                    vol_rate[i, k],
                    dt_tick / n_sub,
                    gas,
                )
                acc += mean
            p_avg[t0 + i + 1] = acc / n_sub
    # Sessions follow each other in the log, separated by a SESSION_GAP_S gap in time.
    time = np.concatenate([k * (options.duration + SESSION_GAP_S) + t_tick for k in range(S)])
    q_true = np.concatenate([fn(t_tick)[0] for fn in q_fns])
    pressure_true = p_avg.reshape(n_ticks + 1, S, C).transpose(1, 0, 2).reshape(-1, C) / KPA
    pressure = pressure_true + offset + rng.normal(0.0, options.pressure_noise, pressure_true.shape)
    # the command sent at each sample (the last one of a session repeated)
    valve_log = np.concatenate([np.vstack([u[:, k], u[-1:, k]]) for k in range(S)])
    pots = _pots(robot, q_true, options, rng)
    truth = Truth(
        params={
            "model": "thin-plate",
            "gas": gas.to_dict(),
            "experiment": options.experiment,
            "sessions": S,
            "substeps": n_sub,
            "valves": {n: _valve_dict(valve, i) for i, n in enumerate(names)},
        },
        effects=effects,
        signals={
            "q": make_stream(robot.joint_names, q_true),
            "pressure": make_stream(names, pressure_true),
        },
    )
    return Log(
        time,
        {
            "pressure": make_stream(names, pressure),
            "valve": make_stream(names, valve_log),
            "pots": pots,
        },
        robot=robot.reference,
        rate_hz=options.rate_hz,
        truth=truth,
    )


def _rate(p, a_c, a_r, supply, room, vol, vol_rate, gas):
    """Eq. (4.4) for all chambers: f = dp/dt (Pa/s), J = df/dp (1/s), supply mass flow (kg/s)."""
    C = p.size
    hi = np.concatenate([np.maximum(supply, p), np.maximum(p, room)])
    lo = np.concatenate([np.minimum(supply, p), np.minimum(p, room)])
    z, dz_hi, dz_lo = z_flow(hi, lo, gas)
    # phi(P_c, p) = z(P_c, p) if P_c >= p else -z(p, P_c); likewise phi(p, P_r), eq. (4.1b)
    fwd_c = supply >= p
    phi_c = np.where(fwd_c, z[:C], -z[:C])
    dphi_c = np.where(fwd_c, dz_lo[:C], -dz_hi[:C])
    fwd_r = p >= room
    phi_r = np.where(fwd_r, z[C:], -z[C:])
    dphi_r = np.where(fwd_r, dz_hi[C:], -dz_lo[C:])
    m_dot = a_c * phi_c - a_r * phi_r  # eq. (4.2)
    dm = a_c * dphi_c - a_r * dphi_r
    gain = gas.kappa * gas.rt_over_m / vol  # eq. (4.4a)
    comp = gas.kappa * vol_rate / vol
    return gain * m_dot - comp * p, gain * dm - comp, np.maximum(a_c * phi_c, 0.0)


def _phi12(z):
    """φ1(z) = (eᶻ - 1)/z and φ2(z) = (eᶻ - 1 - z)/z², stable near z = 0."""
    small = np.abs(z) < 1e-4
    zs = np.where(small, 1.0, z)
    em1 = np.expm1(zs)
    return np.where(small, 1.0 + z / 2.0, em1 / zs), np.where(
        small, 0.5 + z / 6.0, (em1 - zs) / zs**2
    )


def _substep(p, a_c, a_r, supply, room, vol, vol_rate, dt, gas):
    """One exponential-midpoint step of eq. (4.4) for all chambers (Pa).

    Stage 1 (exponential Euler) reaches the half step; stage 2 linearises f there,
    f(p) ≈ f_m + J_m (p - p_m), and solves that exactly over dt: p + dt g φ1(J_m dt) with
    g = f_m + J_m (p - p_m). Returns the new pressure, the mean pressure over the step (exact for
    the linearised dynamics, p + dt g φ2(J_m dt): what the fast-sampling average sees) and the
    supply mass flow (kg/s).
    """
    f, J, _ = _rate(p, a_c, a_r, supply, room, vol, vol_rate, gas)
    phi1, _ = _phi12(0.5 * dt * J)
    p_m = np.maximum(p + 0.5 * dt * f * phi1, 1.0)
    f_m, J_m, m_supply = _rate(p_m, a_c, a_r, supply, room, vol, vol_rate, gas)
    g = f_m + J_m * (p - p_m)
    phi1, phi2 = _phi12(dt * J_m)
    return np.maximum(p + dt * g * phi1, 1.0), p + dt * g * phi2, m_supply


def _joint_motion(robot, cyl, options, rng):
    """q(t), qd(t) for all joints: chamber joints move violently inside their limits and strokes."""
    n = robot.n_joints
    q0 = robot.neutral()
    half = np.zeros(n)
    mid = q0.copy()
    for j in np.unique(cyl.joint_index):
        sel = cyl.joint_index == j
        lo, hi = robot.lower[j], robot.upper[j]
        lim = 0.5 * (hi - lo) if np.isfinite(hi - lo) and hi > lo else 1.0
        mid[j] = cyl.mid[sel][0]
        half[j] = 0.9 * min(lim, float(np.min(0.5 * cyl.stroke[sel] / cyl.moment_arm[sel])))
    if options.experiment == "steady-state":
        half[:] = 0.0  # locked cylinders (§4.3.1)
    f = np.exp(rng.uniform(np.log(0.05), np.log(1.5), (8, n)))
    a = rng.normal(0.0, 1.0, (8, n)) * np.sqrt(2.0 / 8) * 0.9
    ph = rng.uniform(0, 2 * np.pi, (8, n))

    def q_fn(t):
        arg = 2 * np.pi * f[None] * t[:, None, None] + ph[None]
        raw = np.einsum("tkn,kn->tn", np.sin(arg), a)
        draw = np.einsum("tkn,kn->tn", np.cos(arg), a * 2 * np.pi * f)
        th = np.tanh(raw)
        return mid + half * th, half * (1 - th**2) * draw

    return q_fn


def _valve_commands(options, cyl, n_ticks, rng):
    """Commands (n_ticks, C) in [3, 7] V: antagonistic + co-contraction + per-valve random steps."""
    C = cyl.side.size
    if options.experiment == "steady-state":
        # §4.5.2: a slow triangle 3 -> 7 -> 3 V, each valve with its own phase.
        t = np.arange(n_ticks)[:, None] / max(n_ticks - 1, 1) + rng.uniform(0, 0.1, C)[None]
        tri = 1.0 - np.abs(1.0 - 2.0 * (t % 1.0))
        return U_LOW + (U_HIGH - U_LOW) * tri
    joints = np.unique(cyl.joint_index)
    col = np.searchsorted(joints, cyl.joint_index)
    anta = random_steps(rng, n_ticks, joints.size, 30, 1.3)[:, col] * cyl.side
    co = random_steps(rng, n_ticks, joints.size, 100, 0.6)[:, col]
    own = random_steps(rng, n_ticks, C, 20, 0.8)
    t = np.arange(n_ticks) / options.rate_hz
    wobble, _ = smooth_random(rng, t, C, 0.1, 3.0)
    w = anta + co + own + 0.4 * wobble
    return np.clip(5.0 + 2.0 * np.tanh(0.7 * w), U_LOW, U_HIGH)


def _effects(options, names, rng):
    """The requested effects (module docstring); returns (records, valve delay (s), leak area (m²),
    droop gain (kPa per g/s), whether the droop follows the total supply flow, pressure offset
    (kPa)), arrays (C,)."""
    C = len(names)
    delay, leak, droop, offset = np.zeros(C), np.zeros(C), np.zeros(C), np.zeros(C)
    records, shared = [], False
    for req in check_effects(options.effects, "pneumatics"):
        values = dict(EFFECT_DEFAULTS[req.name])
        if req.name == "supply_droop" and req.channel == SHARED_LINE:
            sel, channel, shared = np.ones(C, bool), SHARED_LINE, True
            values["kpa_per_g_s"] = 1.0  # the shared line carries every chamber's flow
        else:
            channel = (
                check_channel(req, names, "chamber") if req.channel else names[int(rng.integers(C))]
            )
            sel = np.array([n == channel for n in names])
        if req.size is not None:
            values[EFFECT_SIZE[req.name]] = float(req.size)
        if req.name == "valve_delay":
            delay[sel] = values["delay_s"]
        elif req.name == "chamber_leak":
            leak[sel] += values["area_m2"]
        elif req.name == "supply_droop":
            droop[sel] = values["kpa_per_g_s"]
        elif req.name == "pressure_offset":
            offset[sel] += values["offset"]
        records.append(effect_record(req.name, channel, values))
    return records, delay, leak, droop, shared, offset


def _pots(robot, q, options, rng):
    pots = robot.sensors.pots
    missing = [
        c.volume_sensor
        for c in robot.sensors.chambers
        if c.volume_sensor not in robot.sensors.pot_names
    ]
    if missing:
        raise RobotConfigError(
            f"sensors.yaml: chamber volume_sensor {missing[0]!r} is not a pot of this robot"
        )
    gain = np.array([p.gain for p in pots])
    bias = np.array([p.bias for p in pots])
    data = predict_pots(robot, q, gain, bias)
    return make_stream(
        robot.sensors.pot_names, data + rng.normal(0.0, options.pot_noise, data.shape)
    )


def _valve_dict(valve: ValveGeometry, i: int) -> dict:
    pick = lambda x: float(np.ravel(x)[i] if np.ndim(x) else x)  # noqa: E731
    return {
        "U_c": pick(valve.U_c),
        "U_r": pick(valve.U_r),
        "L_c_m2": pick(valve.L_c),
        "L_r_m2": pick(valve.L_r),
        "B_m2_per_V": pick(valve.B),
        "smooth_m2": pick(valve.smooth),
    }


def _check_options(o: PneumaticSimOptions) -> None:
    if o.experiment not in EXPERIMENTS:
        raise SimOptionError(
            f"unknown experiment {o.experiment!r} (expected {' or '.join(EXPERIMENTS)})"
        )
    if not o.duration > 0:
        raise SimOptionError(f"duration must be positive, got {o.duration}")
    if o.duration * o.rate_hz < 10:
        raise SimOptionError(
            f"duration {o.duration} s at {o.rate_hz} Hz gives fewer than 10 samples"
        )
    if o.sessions < 1:
        raise SimOptionError(f"sessions must be >= 1, got {o.sessions}")
    if o.substeps < 1:
        raise SimOptionError(f"substeps must be >= 1, got {o.substeps}")
    if o.pressure_noise < 0 or o.pot_noise < 0:
        raise SimOptionError("noise levels must be non-negative")
