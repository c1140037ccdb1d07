"""Does `diagnose` name what was hidden, and stay silent when nothing was? (issue #13, Evidence)

For each domain, ``--logs`` simulated logs each hide one effect of the domain's vocabulary (causes
taken in turn; channel, magnitude and region drawn from the seed) and ``--logs`` clean logs hide
none. Dynamics: a torque of 3-10× the noise on a random joint, as the issue asks. Kinematics: an
effect of 3-10× the noise of the channel it is read on (:func:`_sized_kinematic_effect`: pot noise
for a pot's nonlinearity or backlash, marker noise per axis for the distance a link offset, a slip,
an outlier or a swap moves a marker, and for the RMS distance a clock shift moves the markers); a
link offset is hidden on a joint another joint carries (the offset of a joint hanging from the base
is the mocap frame's, which no calibration can tell apart). Pneumatics: the simulator's physical
default ranges. Every log is diagnosed with the defaults a user gets, except that a
cause the default baseline already contains is diagnosed against a baseline without it
(:data:`BASELINE_FOR`). A hidden effect counts as *named* when the top finding has its cause and
channel (or names that channel as one the data cannot tell from its own) and a positive held-out
gain; a clean log is a *false alarm* when it gives any finding.
A hidden data fault found as a *minor fault* (its writing-off removed under ``min_gain`` of the
held-out error: no finding, as issue #31 item 3 asks) is counted apart, as are clean logs with a
minor fault; *found* counts the named logs and those. A hidden effect
not named is compared with its clean twin (the same run without it): *taken up by the baseline*
when the baseline's held-out error on its channel is within ``TAKEN_UP`` of the twin's (an
identified baseline can hold an effect in its own parameters: an armature in a link's inertia);
counted apart, still a miss. ``--verbose`` prints beside a miss ``left`` (that excess, a share of
the twin's MSE) and ``limit²``: the square of the diagnosis's detection limit of the hidden cause on
its channel over the residual (``detection_limits``): a miss with ``left`` under ``limit²`` was
below what the log could show.
Printed per domain and per cause: the naming rate, the false-alarm rate and the wall time per log
(load average beside it).

Seeds are fresh on every run (printed; ``--seed`` repeats a run). The bench reads each log's
``/truth`` to judge; the diagnosis never sees it (``diagnose`` drops it).

    python bench/bench_diagnose.py                       # all domains, 50 + 50 logs each
    python bench/bench_diagnose.py --domain dynamics --logs 10 --seed 7
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

#: What each domain hides, on which robot, and how long a log is. Pneumatic logs are diagnosed on
#: the hidden effect's chamber and one other drawn at random (two units; the diagnosis treats
#: chambers independently, with its false-alarm rate shared between them).
CASES = {
    "kinematics": {
        "robot": "finger",
        "duration": 30.0,
        "causes": (
            "link_offset",
            "sensor_nonlinearity",
            "backlash",
            "time_offset",
            "marker_slip",
            "marker_outliers",
            "swapped_labels",
        ),
    },
    "dynamics": {
        "robot": "arm3",
        "duration": 30.0,
        "causes": (
            "coulomb_friction",
            "viscous_friction",
            "position_friction",
            "payload",
            "spring",
            "torque_offset",
            "armature",
            "coupled_friction",
            "torque_lag",
            "torque_gain",
            "transmission_backlash",
        ),
    },
    "pneumatics": {
        "robot": "diego",
        "duration": 30.0,
        "causes": ("valve_delay", "chamber_leak", "supply_droop", "pressure_offset"),
    },
}


#: A cause the default baseline contains is hidden against a baseline without it: friction of a
#: kind the model already fits per joint is no model error, nor is a payload (or a link's own
#: inertia error) on a link whose inertial parameters the identified rigid body fits (its baseline
#: keeps the URDF's inertias).
BASELINE_FOR = {
    "coulomb_friction": {"friction": ("viscous",)},
    "viscous_friction": {"friction": ("coulomb",)},
    "payload": {"inertia": "nominal"},
    "link_inertia": {"inertia": "nominal"},
}


#: ... and the robot has none of that friction on its other joints (else the baseline without it
#: rightly names the joint with the most of the simulator's own friction first).
ROBOT_FOR = {"coulomb_friction": {"coulomb": 0.0}, "viscous_friction": {"viscous": 0.0}}
TORQUE_NOISE = 0.01  # N·m, the dynamics simulator's default
POT_NOISE, MARKER_NOISE = 0.005, 0.002  # V and m per axis, the kinematics simulator's defaults
#: A missed effect is taken up by the baseline when the baseline's held-out mean squared error on
#: its channel exceeds its clean twin's by at most this share (the same run, the same noise: an
#: effect the identified parameters hold leaves it equal to rounding).
TAKEN_UP = 0.01


@dataclass(frozen=True)
class Outcome:
    domain: str
    cause: str | None  # None: a clean log
    channel: str | None
    seed: int
    top: str  # "cause:channel" of the top finding, "" when none
    n_findings: int
    gain: float  # held-out reduction of the top finding (NaN when none)
    seconds: float
    error: str = ""
    also: tuple = ()  # other channels that name the same effect (a swapped pair's partner)
    ratio: float = float("nan")  # the hidden effect's size on its channel / that channel's noise
    minor: tuple = ()  # "cause:channel" of each minor fault (found, no finding: it removed under min_gain)
    twins: tuple = ()  # channels the top finding's data cannot tell from its own (its evidence)
    left: float = float("nan")  # not named: the baseline's held-out MSE on its channel over its clean twin's, − 1
    limit: float = float("nan")  # the diagnosis's detection limit of the hidden cause on its channel, over its residual

    @property
    def minor_fault(self) -> bool:
        """The hidden fault was found, but as a minor fault (writing it off removed too little)."""
        return self.cause is not None and bool(
            set(self.minor) & {f"{self.cause}:{c}" for c in (self.channel, *self.also)}
        )

    @property
    def taken_up(self) -> bool:
        """Not named, and the baseline already predicts the hidden effect's channel as well as on
        the clean twin: nothing was left to name."""
        return not self.named and bool(self.left <= TAKEN_UP)

    @property
    def named(self) -> bool:
        if self.cause is None or not self.top:
            return False
        channels = {self.channel, *self.also}
        same = self.top in {f"{self.cause}:{c}" for c in channels} or (
            self.top.split(":")[0] == self.cause and bool(channels & set(self.twins))
        )
        return same and self.gain > 0


def simulate(domain: str, cause: str | None, seed: int, robot_name: str | None = None):
    """A simulated log of ``domain`` hiding ``cause`` (None: clean), and its robot."""
    from diegocal.robot import load_robot, resolve_robot_dir
    from diegocal.sim.effects import check_effects

    case = CASES[domain]
    robot = load_robot(resolve_robot_dir(robot_name or case["robot"], None))
    effects = check_effects([cause] if cause else [], domain)
    rng = np.random.default_rng(seed)
    if domain == "kinematics":
        from diegocal.sim.kinematics import KinematicsOptions, simulate_kinematics

        opts = KinematicsOptions(duration=case["duration"], pot_noise=POT_NOISE, marker_noise=MARKER_NOISE)
        if cause:
            request = _sized_kinematic_effect(robot, cause, seed, opts)
            effects = check_effects([request], domain)
            if cause == "link_offset":  # along the link: the URDF origin's direction
                joint = effects[0].channel
                opts = replace(opts, directions={joint: tuple(_origin(robot, joint))})
        log = simulate_kinematics(robot, replace(opts, effects=effects), rng)
    elif domain == "dynamics":
        from diegocal.sim.dynamics import DynamicsOptions, simulate_dynamics

        opts = DynamicsOptions(duration=case["duration"], noise=TORQUE_NOISE, **ROBOT_FOR.get(cause, {}))
        if cause and cause not in ("payload", "link_inertia"):  # a body's: the simulator's default size
            request, regions = _sized_torque_effect(robot, cause, seed, opts)
            opts = replace(opts, effects=check_effects([request], domain), regions=regions)
        else:
            opts = replace(opts, effects=effects)
        log = simulate_dynamics(robot, opts, rng)
    else:
        from diegocal.sim.pneumatics import PneumaticSimOptions, simulate_pneumatics

        log = simulate_pneumatics(robot, PneumaticSimOptions(duration=case["duration"], effects=effects, seed=seed))
    return log, robot


def _sized_torque_effect(robot, cause: str, seed: int, options) -> tuple[str, dict]:
    """``cause:joint=size`` on a random joint (not the first, whose armature and the like are the
    first link's own inertia) with a torque U(3, 10) × the noise (a lag sized so that lag · RMS(dτ/dt)
    is, a gain error or a load friction's coefficient so that it times RMS(τ) is, a backlash's
    half-width so that it times the torque a radian of play moves is, at most the registry's; a
    Stribeck friction's amplitude, its torque at zero velocity, is), and for position_friction a
    random region, a fifth of the joint's visited range."""
    from diegocal.causes import MAX_BACKLASH_RAD
    from diegocal.sim.dynamics import simulate_dynamics

    rng = np.random.default_rng([seed, 1])
    j = int(rng.integers(1, robot.n_joints))
    joint = robot.joint_names[j]
    ratio = rng.uniform(3.0, 10.0)
    clean = simulate_dynamics(robot, options, np.random.default_rng(seed))  # the same trajectory
    size = ratio * TORQUE_NOISE
    tau = clean.truth.signals["tau"].data[:, j]
    if cause == "torque_lag":
        size /= float(np.sqrt(np.mean(np.gradient(tau, clean.time) ** 2)))
    elif cause in ("torque_gain", "load_friction"):  # the gain error (coefficient) times the joint's RMS torque
        size /= float(np.sqrt(np.mean(tau**2)))
    elif cause == "transmission_backlash":  # the half-width times RMS |dτ/dq_j| over the joints
        size = min(size / _angle_sensitivity(robot, clean, j), MAX_BACKLASH_RAD)
    regions = {}
    if cause == "position_friction":
        lo, hi = np.quantile(clean.stream("q").data[:, j], [0.05, 0.95])
        low = rng.uniform(lo, hi - 0.2 * (hi - lo))
        regions = {joint: (float(low), float(low + 0.2 * (hi - lo)))}
    return f"{cause}:{joint}={size:.6g}", regions


def _angle_sensitivity(robot, log, j: int) -> float:
    """RMS over the samples of |∂τ/∂q_j| (N·m/rad, the norm over the joints) on the log's motion:
    the torque a play of one radian on joint j moves (a backlash's link sits a half-width behind)."""
    import pinocchio as pin

    q, qd, qdd = (log.stream(k).select(robot.joint_names).data for k in ("q", "qd", "qdd"))
    model, data = robot.model, robot.model.createData()
    step = 1e-4
    moved = q.copy()
    moved[:, j] += step
    d = [
        (pin.rnea(model, data, a, v, w) - pin.rnea(model, data, b, v, w)) / step
        for a, b, v, w in zip(moved, q, qd, qdd, strict=True)
    ]
    return float(np.sqrt(np.mean(np.sum(np.square(d), axis=1))))


def _sized_kinematic_effect(robot, cause: str, seed: int, options) -> str:
    """``cause[:channel]=size`` with an effect of U(3, 10) × the noise of the channel it is read on
    (units of the simulator's ``SIZE_UNITS``): a pot nonlinearity's departure at the range's ends
    and a backlash's lag (half its dead band) in pot noise; in marker noise (per axis, m) the
    distance a link offset moves every marker it carries, a slip its marker, an outlier its
    reading, and a swapped pair's distance (the simulator takes the pair nearest it: the realised
    ratio is what :func:`size_ratio` reports); a clock shift of ratio × marker noise / the markers'
    RMS speed (on the clean run of the same seed), so the RMS distance it moves them is ratio ×
    marker noise. Channels are the simulator's seeded choice, except a link offset's: a joint
    another joint carries (a base joint's offset is the mocap frame's)."""
    from diegocal.sim.kinematics import marker_positions, offset_robot, simulate_kinematics
    from diegocal.stac.calibration import Calibration

    rng = np.random.default_rng([seed, 1])
    ratio = rng.uniform(3.0, 10.0)
    if cause == "link_offset":
        carried = [
            j
            for j in robot.joint_names
            if robot.model.parents[robot.model.getJointId(j)] > 0 and np.linalg.norm(_origin(robot, j)) > 0
        ]
        return f"link_offset:{carried[int(rng.integers(len(carried)))]}={ratio * MARKER_NOISE:.6g}"
    if cause == "sensor_nonlinearity":
        return f"{cause}={ratio * POT_NOISE:.6g}"
    if cause == "backlash":
        return f"{cause}={2.0 * ratio * POT_NOISE:.6g}"
    if cause == "time_offset":
        clean = simulate_kinematics(robot, options, np.random.default_rng(seed))  # the same run
        truth = Calibration.from_dict(clean.truth.params)
        x = marker_positions(offset_robot(robot, {}), clean.truth.signals["q"].data, truth)
        speed = np.linalg.norm(np.gradient(x, clean.time, axis=0), axis=-1)
        return f"time_offset:markers={ratio * MARKER_NOISE / float(np.sqrt(np.mean(speed**2))):.6g}"
    return f"{cause}={ratio * MARKER_NOISE:.6g}"


def _origin(robot, joint: str) -> np.ndarray:
    """The joint's origin in its parent joint's frame (URDF ``<origin xyz>``), m: a link offset
    along it makes the link longer or shorter."""
    return np.array(robot.model.jointPlacements[robot.model.getJointId(joint)].translation, float)


def size_ratio(effect: dict) -> float:
    """The hidden effect's realised size on its channel over that channel's noise (from /truth)."""
    v = effect["values"]
    size = {
        "link_offset": lambda: np.linalg.norm(v["dxyz"]) / MARKER_NOISE,
        "marker_slip": lambda: np.linalg.norm(v["dxyz"]) / MARKER_NOISE,
        "sensor_nonlinearity": lambda: abs(v["peak"]) / POT_NOISE,
        "backlash": lambda: 0.5 * v["width_reading"] / POT_NOISE,
        "time_offset": lambda: v["displacement_rms"] / MARKER_NOISE,
        "marker_outliers": lambda: v["distance"][0] / MARKER_NOISE,
        "swapped_labels": lambda: v["distance"] / MARKER_NOISE,
    }.get(effect["cause"])
    return float(size()) if size else float("nan")


def _chambers(log, robot, channel: str | None, seed: int) -> tuple[str, ...]:
    names = [c.name for c in robot.sensors.chambers]
    rng = np.random.default_rng(seed + 1)
    other = [n for n in names if n != channel]
    pick = [channel] if channel in names else [str(rng.choice(other))]
    return (*pick, str(rng.choice([n for n in other if n not in pick])))


def run_one(domain: str, cause: str | None, seed: int, robot_name: str | None = None) -> Outcome:
    """Simulate, diagnose with the defaults, judge against ``/truth``."""
    from diegocal.diagnose import DiagnoseOptions, diagnose
    from diegocal.errors import DiegocalError

    log, robot = simulate(domain, cause, seed, robot_name)
    hidden = log.truth.effects[0] if cause else {}
    channel = hidden.get("channel")
    also = (hidden["values"]["partner"],) if cause == "swapped_labels" else ()  # a swap names either label
    ratio = size_ratio(hidden) if domain == "kinematics" and cause else float("nan")
    options = replace(DiagnoseOptions(domain=domain), **BASELINE_FOR.get(cause, {}))
    if domain == "pneumatics":
        options = replace(options, chambers=_chambers(log, robot, channel, seed))
    start = time.perf_counter()
    try:
        result = diagnose(log, robot, options)
    except DiegocalError as exc:
        return Outcome(
            domain, cause, channel, seed, "", 0, float("nan"), time.perf_counter() - start, str(exc), also, ratio
        )
    seconds = time.perf_counter() - start
    findings = result.findings
    top, gain = "", float("nan")
    if findings:
        top = f"{findings[0].cause}:{findings[0].channel}"
        gain = float(findings[0].gain().get("reduction", float("nan")))
    minor = tuple(f"{f.cause}:{f.channel}" for u in result.units for f in u.minor_faults)
    twins = tuple(findings[0].evidence.get("indistinguishable_from", ())) if findings else ()
    limit = next((d["of_residual"] for u in result.units for d in u.detection_limits
                  if (d["cause"], d["channel"], d["seen_on"]) == (cause, channel, channel)), float("nan"))
    outcome = Outcome(
        domain,
        cause,
        channel,
        seed,
        top,
        len(findings),
        gain,
        seconds,
        also=also,
        ratio=ratio,
        minor=minor,
        twins=twins,
        limit=limit,
    )
    if cause and not outcome.named:  # a miss: what did the baseline leave of the effect?
        twin, _ = simulate(domain, None, seed, robot_name)
        outcome = replace(outcome, left=_left(result, diagnose(twin, robot, options), channel))
    return outcome


def _left(result, twin, channel: str) -> float:
    """The baseline's held-out MSE on ``channel`` over the clean twin's, − 1 (NaN: not scored)."""
    mse = []
    for r in (result, twin):
        score = next((u.baseline_score for u in r.units if channel in u.baseline_score.channels), None)
        if score is None:
            return float("nan")
        mse.append(float(score.rmse[list(score.channels).index(channel)]) ** 2)
    return mse[0] / mse[1] - 1.0


def plan(domain: str, n_logs: int, seed: int) -> list[tuple[str, str | None, int]]:
    """``n_logs`` hidden-effect logs (causes in turn) and ``n_logs`` clean ones, fresh seeds."""
    causes = CASES[domain]["causes"]
    seeds = np.random.SeedSequence(seed).generate_state(2 * n_logs)
    hidden = [(domain, causes[i % len(causes)], int(seeds[i])) for i in range(n_logs)]
    clean = [(domain, None, int(seeds[n_logs + i])) for i in range(n_logs)]
    return hidden + clean


def table(outcomes: list[Outcome]) -> str:
    rows = [
        "| domain | cause | logs | named | false alarms | size / noise | s per log (median) | errors |",
        "|---|---|---|---|---|---|---|---|",
    ]
    by = {}
    for o in outcomes:
        by.setdefault((o.domain, o.cause or "(clean)"), []).append(o)
    for (domain, cause), group in sorted(by.items(), key=lambda kv: (kv[0][0], kv[0][1] == "(clean)", kv[0][1])):
        n = len(group)
        named = sum(o.named for o in group) if cause != "(clean)" else None
        minor = sum(o.minor_fault and not o.named for o in group) if cause != "(clean)" else None
        taken = sum(o.taken_up for o in group) if cause != "(clean)" else None
        alarms = sum(o.n_findings > 0 for o in group) if cause == "(clean)" else None
        sec = float(np.median([o.seconds for o in group]))
        errs = sum(bool(o.error) for o in group)
        ratios = [o.ratio for o in group if np.isfinite(o.ratio)]
        size = f"{min(ratios):.1f}-{max(ratios):.1f}" if ratios else ""
        rows.append(
            f"| {domain} | {cause} | {n} | {'' if named is None else f'{named}/{n}'}"
            f"{f' (+{minor} minor fault)' if minor else ''}{f' ({taken} taken up by the baseline)' if taken else ''} | "
            f"{'' if alarms is None else f'{alarms}/{n}'} | {size} | {sec:.1f} | {errs} |"
        )
    for domain in sorted({o.domain for o in outcomes}):
        hid = [o for o in outcomes if o.domain == domain and o.cause]
        cln = [o for o in outcomes if o.domain == domain and not o.cause]
        rate = sum(o.named for o in hid) / max(len(hid), 1)
        fa = sum(o.n_findings > 0 for o in cln) / max(len(cln), 1)
        minor = sum(o.minor_fault and not o.named for o in hid)
        taken = sum(o.taken_up for o in hid)
        found = (sum(o.named for o in hid) + minor) / max(len(hid), 1)
        rows.append(
            f"| **{domain}** | all | {len(hid)} + {len(cln)} | **{rate:.0%}** (goal ≥ 90 %)"
            f"{f'; {found:.0%} found, +{minor} hidden faults said as minor faults' if minor else ''}"
            f"{f'; {taken} of the misses taken up by the baseline' if taken else ''} | "
            f"**{fa:.0%}** (goal ≤ 5 %){f'; {sum(bool(o.minor) for o in cln)} with a minor fault' if cln else ''} | | "
            f"{np.median([o.seconds for o in hid + cln]):.1f} | |"
        )
    return "\n".join(rows)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--domain", action="append", choices=tuple(CASES), help="Domain (repeatable); default all.")
    parser.add_argument("--logs", type=int, default=50, help="Hidden-effect logs per domain (and as many clean).")
    parser.add_argument("--seed", type=int, default=None, help="Repeat a run (default: fresh seeds, printed).")
    parser.add_argument("--jobs", type=int, default=1, help="Logs diagnosed in parallel processes.")
    parser.add_argument("--verbose", action="store_true", help="One line per log.")
    args = parser.parse_args(argv)
    if args.logs < 1:
        print("error: --logs must be at least 1", file=sys.stderr)
        return 2
    seed = args.seed if args.seed is not None else int(np.random.SeedSequence().entropy % 2**31)
    domains = args.domain or list(CASES)
    print(f"bench_diagnose: seed {seed}, {args.logs} + {args.logs} logs per domain, load {os.getloadavg()[0]:.1f}")
    jobs = [job for d in domains for job in plan(d, args.logs, seed)]
    outcomes = []
    if args.jobs > 1:
        with ProcessPoolExecutor(max_workers=args.jobs) as pool:
            outcomes = list(pool.map(run_one, *zip(*jobs, strict=True)))
    else:
        outcomes = [run_one(*job) for job in jobs]
    if args.verbose:
        for o in outcomes:
            verdict = "named" if o.named else ("alarm" if (o.cause is None and o.n_findings) else "")
            print(
                f"{o.domain:10s} {str(o.cause):20s} {str(o.channel):16s} seed {o.seed:<12d} top {o.top or '-':40s} "
                f"gain {o.gain:6.2f} {o.seconds:6.1f} s size/noise {o.ratio:5.1f} left {o.left:6.3f} "
                f"limit² {o.limit**2:6.3f} {verdict} "
                f"{o.error}"
            )
    print(table(outcomes))
    print(f"load average at the end: {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
