"""Static-pose sessions of robots whose link geometry is off, written apart from the estimator
(it imports nothing of ``diegocal.stac`` or ``diegocal.sim``): the evidence for ``stac --geometry``
(issue #34).

The robot: a URDF of ``example-robot-data`` (the Panda arm, 7 joints; Talos's torso and left arm,
9 joints: the issue's real case) with an encoder on each joint of the chain and one or a few
points on the tool measured in 3-D. The hardware (``hardware_seed``): every joint's placement in
its parent is off by a rigid motion, the URDF's ``<origin>`` composed with
``Translation(d) · RPY(a, b, c)`` (d ~ N(0, ``link_mm``) per axis, roll-pitch-yaw ~ N(0,
``axis_deg``)), applied to the Pinocchio model directly; the encoders' zeros are off by
U(±0.02) rad (``kind="rotary"``: pots of gain U(0.97, 1.03) instead of encoders); the tool
points U(±5 mm) from where sensors.yaml puts them; the mocap frame a rotation about the vertical
of any angle with a few degrees of tilt, 1-2 m away. A session
(``seed``): poses uniform in the central 80 % of each joint's range (one sample each: snapshots
2 s apart), encoder noise N(0, ``encoder_noise``) rad, marker noise N(0, ``marker_noise``) m;
``wrong`` poses filed with another pose's markers.

``/truth``: ``params`` {geometry: {joint: {xyz, rpy}}, encoder_bias, markers, mocap: {R, T}} in
this generator's own form, and the signals ``q`` (true angles), ``markers_clean`` (noise-free
markers) and ``markers_floor`` (the true model at the angles the encoders give, their true
zeros removed: what a perfect calibration predicts, so the distance to the readings is the
noise floor of a held-out pose).
"""

from __future__ import annotations

import argparse
import sysconfig
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin
import yaml

from diegocal.io import Log, Truth, make_stream, save_log

SHARE = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix" / "share" / "example-robot-data" / "robots"
#: name -> (URDF, the chain's joints, the tool link)
ROBOTS = {
    "panda": ("panda_description/urdf/panda.urdf", tuple(f"panda_joint{i}" for i in range(1, 8)), "panda_hand"),
    "talos": (
        "talos_data/robots/talos_reduced.urdf",
        ("torso_1_joint", "torso_2_joint") + tuple(f"arm_left_{i}_joint" for i in range(1, 8)),
        "gripper_left_base_link",
    ),
}
RATE = 100.0


@dataclass(frozen=True)
class Session:
    """What to generate: robot name, poses, tool points, noise (rad, m), hardware error sizes."""

    robot: str = "panda"
    n_poses: int = 60
    points: int = 1
    encoder_noise: float = 2e-5
    marker_noise: float = 3e-4
    link_mm: float = 2.0
    axis_deg: float = 0.3
    seed: int = 0
    hardware_seed: int = 1
    wrong: int = 0
    kind: str = "encoder"


def robot_dir(out: Path, session: Session) -> Path:
    """``out/<robot>/`` (robot.urdf, sensors.yaml): encoders on the chain (nominal zero 0), the tool
    points 5-15 cm beyond the tool link's origin."""
    urdf, joints, tool = ROBOTS[session.robot]
    rng = np.random.default_rng(session.hardware_seed + 1000)
    d = Path(out) / session.robot
    d.mkdir(parents=True, exist_ok=True)
    (d / "robot.urdf").write_bytes((SHARE / urdf).read_bytes())
    model = pin.buildModelFromUrdf(str(SHARE / urdf))
    root = next(f.name for f in model.frames if f.type == pin.FrameType.BODY)
    points = [
        {
            "name": f"tool{k}",
            "link": tool,
            "xyz": [float(v) for v in np.r_[rng.uniform(-0.03, 0.03, 2), rng.uniform(0.05, 0.15)]],
        }
        for k in range(session.points)
    ]
    sensors = {
        "urdf": "robot.urdf",
        "base_link": root,
        "pots": [{"name": f"{j}_enc", "kind": session.kind, "joint": j, "bias": 0.0} for j in joints],
        "markers": points,
    }
    (d / "sensors.yaml").write_text(yaml.safe_dump(sensors, sort_keys=False))
    return d


def _hardware(model: pin.Model, joints, session: Session, nominal_xyz: np.ndarray):
    rng = np.random.default_rng(session.hardware_seed)
    geometry = {
        j: {"xyz": rng.normal(0.0, session.link_mm * 1e-3, 3), "rpy": rng.normal(0.0, np.deg2rad(session.axis_deg), 3)}
        for j in joints
    }
    bias = rng.uniform(-0.02, 0.02, len(joints))
    gain = rng.uniform(0.97, 1.03, len(joints)) if session.kind == "rotary" else np.ones(len(joints))
    xyz = nominal_xyz + rng.uniform(-0.005, 0.005, nominal_xyz.shape)
    yaw = rng.uniform(-np.pi, np.pi)
    R = pin.rpy.rpyToMatrix(*rng.normal(0.0, np.deg2rad(3.0), 2), yaw)
    T = rng.uniform(1.0, 2.0, 3) * rng.choice([-1, 1], 3)
    return geometry, bias, gain, xyz, R, T


def true_model(model: pin.Model, geometry: dict) -> pin.Model:
    """The URDF's model with each joint's placement composed with Translation(xyz) · RPY(rpy)."""
    model = pin.Model(model)
    for j, g in geometry.items():
        jid = model.getJointId(j)
        model.jointPlacements[jid] = model.jointPlacements[jid] * pin.SE3(pin.rpy.rpyToMatrix(*g["rpy"]), g["xyz"])
    return model


def tool_points(model: pin.Model, joints, tool: str, xyz: np.ndarray, R, T, q_chain: np.ndarray) -> np.ndarray:
    """Points (K, N, 3) in the mocap frame at chain angles q_chain (K, n) (other joints at 0)."""
    data = model.createData()
    fid = model.getFrameId(tool)
    idx = [model.idx_qs[model.getJointId(j)] for j in joints]
    out = np.empty((q_chain.shape[0], xyz.shape[0], 3))
    for k, qk in enumerate(q_chain):
        q = pin.neutral(model)
        q[idx] = qk
        pin.framesForwardKinematics(model, data, q)
        oMf = data.oMf[fid]
        out[k] = (xyz @ oMf.rotation.T + oMf.translation) @ R.T + T
    return out


def simulate(out: Path, session: Session, q: np.ndarray | None = None) -> tuple[Path, Log]:
    """Write the robot directory and return it with the session's log (module docstring); ``q``
    (n_poses, n) rad: the chain's poses (default: drawn)."""
    d = robot_dir(out, session)
    urdf, joints, tool = ROBOTS[session.robot]
    nominal = pin.buildModelFromUrdf(str(SHARE / urdf))
    sensors = yaml.safe_load((d / "sensors.yaml").read_text())
    nominal_xyz = np.array([m["xyz"] for m in sensors["markers"]], float)
    geometry, bias, gain, xyz, R, T = _hardware(nominal, joints, session, nominal_xyz)
    model = true_model(nominal, geometry)
    rng = np.random.default_rng(session.seed)
    idx = [model.idx_qs[model.getJointId(j)] for j in joints]
    lo, hi = model.lowerPositionLimit[idx], model.upperPositionLimit[idx]
    mid, half = 0.5 * (lo + hi), 0.4 * (hi - lo)
    drawn = rng.uniform(mid - half, mid + half, (session.n_poses, len(joints)))
    q = drawn if q is None else np.asarray(q, float).reshape(session.n_poses, len(joints))
    enc = gain * q + bias + rng.normal(0.0, session.encoder_noise, q.shape)
    clean = tool_points(model, joints, tool, xyz, R, T, q)
    x = clean + rng.normal(0.0, session.marker_noise, clean.shape)
    wrong = np.sort(rng.choice(session.n_poses, session.wrong, replace=False))
    for k in wrong:  # filed with another pose's markers (a labelling or clock mix-up)
        x[k] = clean[(k + session.n_poses // 2) % session.n_poses] + rng.normal(0.0, session.marker_noise, x[k].shape)
    floor = tool_points(model, joints, tool, xyz, R, T, (enc - bias) / gain)
    names = [m["name"] for m in sensors["markers"]]
    pots = [p["name"] for p in sensors["pots"]]
    params = {
        "geometry": {j: {"xyz": g["xyz"].tolist(), "rpy": g["rpy"].tolist()} for j, g in geometry.items()},
        "encoder_bias": dict(zip(pots, bias.tolist(), strict=True)),
        "pot_gain": dict(zip(pots, gain.tolist(), strict=True)),
        "markers": {n: v.tolist() for n, v in zip(names, xyz, strict=True)},
        "mocap": {"R": R.tolist(), "T": T.tolist()},
        "noise": {"encoder": session.encoder_noise, "markers": session.marker_noise},
        "wrong_poses": wrong.tolist(),
    }
    signals = {
        "q": make_stream(list(joints), q),
        "markers_clean": make_stream(names, clean),
        "markers_floor": make_stream(names, floor),
    }
    log = Log(
        time=np.arange(session.n_poses) * 2.0,
        streams={"pots": make_stream(pots, enc), "markers": make_stream(names, x)},
        robot=str(d.resolve()),
        rate_hz=RATE,
        truth=Truth(params=params, effects=[], signals=signals),
    )
    return d, log


def candidate_poses(session: Session, n: int, seed: int) -> np.ndarray:
    """n candidate poses (n, joints) rad, uniform in the central 80 % of each joint's range."""
    urdf, joints, _ = ROBOTS[session.robot]
    model = pin.buildModelFromUrdf(str(SHARE / urdf))
    idx = [model.idx_qs[model.getJointId(j)] for j in joints]
    lo, hi = model.lowerPositionLimit[idx], model.upperPositionLimit[idx]
    mid, half = 0.5 * (lo + hi), 0.4 * (hi - lo)
    return np.random.default_rng(seed).uniform(mid - half, mid + half, (n, len(joints)))


def truth_of(names, R_start: np.ndarray, params: dict) -> np.ndarray:
    """The truth (p,) of parameters named as ``stac --geometry`` names them (``frame.x``,
    ``frame.rx`` a left rotation vector from ``R_start``, ``<pot>.bias``, ``<marker>.x``,
    ``joint_geometry:<joint>.dx`` .. ``.rz``: Translation · RPY as (xyz, log3(RPY))), from this
    generator's own record ``params``."""
    out = []
    for name in names:
        owner, what = name.rsplit(".", 1)
        if owner == "frame":
            rot = pin.log3(np.array(params["mocap"]["R"]) @ np.asarray(R_start).T)
            out.append(np.r_[params["mocap"]["T"], rot][["x", "y", "z", "rx", "ry", "rz"].index(what)])
        elif owner.startswith("joint_geometry:"):
            g = params["geometry"][owner.split(":")[1]]
            v = np.r_[g["xyz"], pin.log3(pin.rpy.rpyToMatrix(*g["rpy"]))]
            out.append(v[["dx", "dy", "dz", "rx", "ry", "rz"].index(what)])
        elif what == "bias":
            out.append(params["encoder_bias"][owner])
        elif what == "gain":
            out.append(params["pot_gain"][owner])
        else:
            out.append(params["markers"][owner]["xyz".index(what)])
    return np.array(out)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--robot", choices=sorted(ROBOTS), default="panda")
    ap.add_argument("--poses", type=int, default=60)
    ap.add_argument("--points", type=int, default=1)
    ap.add_argument("--marker-noise", type=float, default=3e-4)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--hardware-seed", type=int, default=1)
    ap.add_argument("--link-mm", type=float, default=2.0, help="joint placement error per axis, mm (0: none)")
    ap.add_argument("--axis-deg", type=float, default=0.3, help="joint placement error per angle, deg (0: none)")
    ap.add_argument("--wrong", type=int, default=0, help="poses filed with another pose's markers")
    ap.add_argument("--kind", choices=("encoder", "rotary"), default="encoder")
    a = ap.parse_args(argv)
    session = Session(
        a.robot,
        a.poses,
        a.points,
        marker_noise=a.marker_noise,
        link_mm=a.link_mm,
        axis_deg=a.axis_deg,
        seed=a.seed,
        hardware_seed=a.hardware_seed,
        wrong=a.wrong,
        kind=a.kind,
    )
    d, log = simulate(a.out, session)
    save_log(log, a.out / f"{a.robot}_static.h5")
    print(d, a.out / f"{a.robot}_static.h5")


if __name__ == "__main__":
    main()
