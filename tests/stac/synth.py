"""Small self-contained robots and logs with ground truth for the STAC tests and bench.

A tree of chains hung from ``waist``: rotary joints with rotary pots, 2-DoF gimbals read by two
linear pots (thesis Fig. 2.3d), markers on every other link (§2.5.1), or a tendon finger (§2.3.3).
Data follow the observation models of ``diegocal.robot.observe`` with explicit, seeded noise.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from diegocal.io import Log, Truth, make_stream, save_yaml, write_text
from diegocal.robot import load_robot, predict_markers, predict_pots
from diegocal.stac.calibration import Calibration

AXES = ("0 0 1", "0 1 0", "1 0 0")
#: diego-like: 38 joints = 30 rotary + 4 gimbals (8 joints, 8 linear pots)
DIEGO_CHAINS = (
    ("neck", "grr"),
    ("larm", "grrrrrr"),
    ("rarm", "grrrrrr"),
    ("lleg", "grrrrrrr"),
    ("rleg", "grrrrrrr"),
)
SMALL_CHAINS = (("neck", "gr"), ("arm", "rrrr"))


def _link(name):
    return (
        f'<link name="{name}"><inertial><mass value="0.1"/><origin xyz="0 0 0"/>'
        '<inertia ixx="1e-4" iyy="1e-4" izz="1e-4" ixy="0" ixz="0" iyz="0"/></inertial></link>'
    )


def _joint(name, parent, child, xyz, axis, lim):
    return (
        f'<joint name="{name}" type="revolute"><parent link="{parent}"/><child link="{child}"/>'
        f'<origin xyz="{xyz[0]:.4f} {xyz[1]:.4f} {xyz[2]:.4f}" rpy="0 0 0"/><axis xyz="{axis}"/>'
        f'<limit lower="{-lim}" upper="{lim}" effort="10" velocity="10"/></joint>'
    )


def make_tree_robot(directory, chains=SMALL_CHAINS, seed: int = 0, markers_on_base: bool = False):
    """Write robot.urdf + sensors.yaml of a tree robot; return the directory."""
    rng = np.random.default_rng(seed)
    directory = Path(directory)
    links, joints, pots, markers = [_link("waist")], [], [], []
    for c, (chain, spec) in enumerate(chains):
        direction = np.array([np.cos(c * 1.3), np.sin(c * 1.3), 0.4 * (c % 2) - 0.2])
        direction /= np.linalg.norm(direction)
        parent, depth, k = "waist", 0, 0
        for s, kind in enumerate(spec):
            offset = 0.09 * direction + rng.uniform(-0.02, 0.02, 3)
            child = f"{chain}{s}"
            if kind == "g":  # gimbal: two joints through a massless middle link, two linear pots
                mid = f"{child}_mid"
                links += [_link(mid), _link(child)]
                joints.append(_joint(f"{chain}{s}_a", parent, mid, offset, "1 0 0", 0.6))
                joints.append(_joint(f"{chain}{s}_b", mid, child, (0, 0, 0), "0 1 0", 0.6))
                for side, y in (("l", 0.03), ("r", -0.03)):
                    pots.append(
                        {
                            "name": f"{chain}{s}_{side}",
                            "kind": "linear",
                            "gain": 20.0,
                            "bias": 0.0,
                            "anchors": [
                                {"link": parent, "xyz": (offset + [0.0, y, -0.05]).tolist()},
                                {"link": child, "xyz": [0.03, y, 0.04]},
                            ],
                        }
                    )
                depth += 2
            else:
                links.append(_link(child))
                joints.append(_joint(f"j_{chain}{s}", parent, child, offset, AXES[k % 3], 1.4))
                pots.append(
                    {
                        "name": f"{chain}{s}",
                        "kind": "rotary",
                        "joint": f"j_{chain}{s}",
                        "gain": 1.0,
                        "bias": 0.0,
                    }
                )
                depth += 1
            k += 1
            last = s == len(spec) - 1
            if depth % 2 == 0 or last:
                markers.append(
                    {
                        "name": f"m_{child}",
                        "link": "waist" if markers_on_base else child,
                        "xyz": (rng.choice([-1, 1], 3) * rng.uniform(0.03, 0.06, 3)).round(4).tolist(),
                    }
                )
            parent = child
    urdf = '<?xml version="1.0"?>\n<robot name="synth">\n' + "\n".join(links + joints) + "\n</robot>\n"
    directory.mkdir(parents=True, exist_ok=True)
    write_text(directory / "robot.urdf", urdf)
    save_yaml(
        {"urdf": "robot.urdf", "base_link": "waist", "pots": pots, "markers": markers},
        directory / "sensors.yaml",
    )
    return directory


def make_finger_robot(directory, seed: int = 0):
    """A tendon finger (§2.3.3, Fig. 2.3e): 4 joints with Hall sensors, 3 tendons, 4 markers."""
    rng = np.random.default_rng(seed)
    directory = Path(directory)
    names = ["palm", "prox_base", "prox", "mid", "dist"]
    links = [_link(n) for n in names]
    joints = [
        _joint("mcp_abd", "palm", "prox_base", (0.0, 0.0, 0.09), "1 0 0", 0.4),
        _joint("mcp", "prox_base", "prox", (0.0, 0.0, 0.0), "0 1 0", 1.4),
        _joint("pip", "prox", "mid", (0.0, 0.0, 0.045), "0 1 0", 1.4),
        _joint("dip", "mid", "dist", (0.0, 0.0, 0.028), "0 1 0", 1.2),
    ]
    pots = [
        {"name": f"hall_{j}", "kind": "rotary", "joint": j, "gain": 1.0, "bias": 0.0}
        for j in ("mcp_abd", "mcp", "pip", "dip")
    ]
    pots += [
        {
            "name": "flex",
            "kind": "tendon",
            "gain": 1.0,
            "bias": 0.0,
            "moment_arms": {"mcp": 0.010, "pip": 0.008, "dip": 0.006},
        },
        {
            "name": "ext",
            "kind": "tendon",
            "gain": 1.0,
            "bias": 0.0,
            "moment_arms": {"mcp": -0.008, "pip": -0.005, "dip": -0.004},
        },
        {
            "name": "abd",
            "kind": "tendon",
            "gain": 1.0,
            "bias": 0.0,
            "moment_arms": {"mcp_abd": 0.007},
        },
    ]
    markers = [
        {"name": f"m_{n}{i}", "link": n, "xyz": rng.uniform(-0.015, 0.015, 3).round(4).tolist()}
        for n in ("prox", "mid", "dist")
        for i in range(2)
    ]
    urdf = '<?xml version="1.0"?>\n<robot name="finger">\n' + "\n".join(links + joints) + "\n</robot>\n"
    directory.mkdir(parents=True, exist_ok=True)
    write_text(directory / "robot.urdf", urdf)
    save_yaml(
        {"urdf": "robot.urdf", "base_link": "palm", "pots": pots, "markers": markers},
        directory / "sensors.yaml",
    )
    return directory


def smooth_q(robot, n_frames: int, rate_hz: float, rng) -> np.ndarray:
    """Smooth random joint trajectories inside 85 % of the limits: (T, n) rad."""
    t = np.arange(n_frames) / rate_hz
    mid, half = 0.5 * (robot.lower + robot.upper), 0.5 * (robot.upper - robot.lower) * 0.85
    q = np.zeros((n_frames, robot.n_joints))
    for _ in range(3):
        f = rng.uniform(0.03, 0.4, robot.n_joints)
        ph = rng.uniform(0, 2 * np.pi, robot.n_joints)
        q += np.sin(2 * np.pi * f * t[:, None] + ph) / 3
    return mid + half * np.clip(q, -1, 1)


def true_calibration(robot, rng, gain_err=0.2, bias_err=0.3) -> Calibration:
    """Gains off by up to ±gain_err, biases by up to ±bias_err rad (pot units), random mocap."""
    nom = Calibration.nominal(robot)
    kinds = [p.kind for p in robot.sensors.pots]
    scale = np.array([{"rotary": 1.0, "encoder": 1.0, "linear": 0.01, "tendon": 0.01}[k] for k in kinds])
    gain = nom.gain * (1 + rng.uniform(-gain_err, gain_err, len(kinds)))
    gain[np.array(kinds) == "encoder"] = 1.0
    bias = nom.bias + rng.uniform(-bias_err, bias_err, len(kinds)) * scale * np.abs(nom.gain)
    angles = rng.uniform(-0.5, 0.5, 3)
    from scipy.spatial.transform import Rotation

    xyz = nom.marker_xyz + rng.uniform(-0.02, 0.02, nom.marker_xyz.shape)
    return Calibration(
        nom.pot_names,
        gain,
        bias,
        nom.marker_names,
        nom.marker_links,
        xyz,
        mocap_R=Rotation.from_rotvec(angles).as_matrix(),
        mocap_T=rng.uniform(-1, 1, 3),
        sigma_pots=0.005,
        sigma_markers=0.001,
        method="truth",
        pot_units=nom.pot_units,
    )


def simulate(
    robot,
    n_frames=2000,
    rate_hz=100.0,
    seed=0,
    sigma_pots=0.005,
    sigma_markers=0.001,
    occlusion=0.0,
    truth: Calibration | None = None,
    marker_time: float = 0.0,
) -> Log:
    """A log of pots (V) and markers (m, NaN when occluded) with /truth (params + q); marker noise
    white, or with ``marker_time`` > 0 (s) an AR(1) process of that correlation time (the same σ)."""
    rng = np.random.default_rng(seed)
    truth = truth or true_calibration(robot, rng)
    q = smooth_q(robot, n_frames, rate_hz, rng)
    tendon = np.array([p.kind == "tendon" for p in robot.sensors.pots])
    noise = np.where(tendon, 0.04 * sigma_pots, sigma_pots)  # tendons read metres, not volts
    pots = predict_pots(robot, q, truth.gain, truth.bias) + rng.normal(0, 1, (n_frames, len(truth.gain))) * noise
    mk = predict_markers(robot, q, truth.marker_xyz, truth.mocap_R, truth.mocap_T)
    e = rng.normal(0, sigma_markers, mk.shape)
    if marker_time > 0:  # x_t = a x_(t-1) + sqrt(1 - a²) e_t: stationary with σ, correlated over marker_time
        a = np.exp(-1.0 / (marker_time * rate_hz))
        for t in range(1, n_frames):
            e[t] = a * e[t - 1] + np.sqrt(1 - a * a) * e[t]
    mk = mk + e
    if occlusion:
        mk[rng.random(mk.shape[:2]) < occlusion] = np.nan
    streams = {
        "pots": make_stream(truth.pot_names, pots),
        "markers": make_stream(truth.marker_names, mk),
    }
    params = truth.to_dict()
    return Log(
        np.arange(n_frames) / rate_hz,
        streams,
        robot=robot.name,
        rate_hz=rate_hz,
        truth=Truth(params=params, signals={"q": make_stream(robot.joint_names, q)}),
    )


def load(directory):
    return load_robot(directory)


def q_step_start(robot, frames: int):
    """A log of ``frames`` frames and a q-step's start on it: (log, Observation, nominal θ, Noise,
    q0 (the truth perturbed by 0.2 rad, clipped to the limits), λ)."""
    from diegocal.stac.model import Observation
    from diegocal.stac.qphase import Noise

    log = simulate(robot, frames, seed=5, occlusion=0.3)
    obs = Observation(log, robot)
    q0 = log.truth.signals["q"].data + np.random.default_rng(4).normal(0.0, 0.2, (obs.n_frames, robot.n_joints))
    noise = Noise(np.full(obs.n_pots, 0.01), 0.002)
    return log, obs, obs.nominal("nominal"), noise, np.clip(q0, obs.lower, obs.upper), np.full(obs.n_frames, 1e-2)
