"""Robots diegocal did not design: URDFs from the ``example-robot-data`` package (Pinocchio's
collection, real inertias), turned into robot directories with a sensors.yaml written here.

``robot_dir(tmp_path, "ur5")`` copies the URDF and writes a sensors.yaml with a rotary pot on every
joint (gains near 1 V/rad, small biases) and markers on only some links (every other moving link,
three markers each, a few centimetres from the link origin), the way a lab would instrument a
robot it bought. Tests that need these robots skip when the package is not installed.
"""

from __future__ import annotations

import shutil
import sysconfig
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import yaml

SHARE = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix" / "share" / "example-robot-data" / "robots"
URDFS = {
    "ur5": "ur_description/urdf/ur5_joint_limited_robot.urdf",
    "panda": "panda_description/urdf/panda.urdf",
    "icub": "icub_description/robots/icub_reduced.urdf",
    "icub_full": "icub_description/robots/icub.urdf",  # 32 joints: the neck too
    "talos_arm": "talos_data/robots/talos_left_arm.urdf",
}


def urdf_path(name: str) -> Path:
    """The package's URDF of robot ``name``; skips the calling test when it is not installed."""
    path = SHARE / URDFS[name]
    if not path.is_file():
        pytest.skip(f"example-robot-data is not installed (no {URDFS[name]})")
    return path


def robot_dir(
    tmp_path: Path,
    name: str,
    marker_every: int = 2,
    markers_per_link: int = 3,
    seed: int = 0,
    joints: tuple[str, ...] | None = None,
) -> Path:
    """A robot directory (robot.urdf + sensors.yaml) for ``name`` under ``tmp_path``.

    Pots: a rotary pot on every joint of ``joints`` (default: every revolute joint), gain
    U(0.8, 1.2) V/rad, bias U(-0.2, 0.2) V. Markers: on every ``marker_every``-th moving link
    (counted along the joint order, the last link always included), ``markers_per_link`` each at
    U(-0.05, 0.05) m from the link's origin. ``base_link`` is the URDF's root link.
    """
    rng = np.random.default_rng(seed)
    src = urdf_path(name)
    out = tmp_path / name
    out.mkdir(parents=True, exist_ok=True)
    shutil.copy(src, out / "robot.urdf")
    model = pin.buildModelFromUrdf(str(src))
    root = next(f.name for f in model.frames if f.type == pin.FrameType.BODY)
    revolute = [
        model.names[j] for j in range(1, model.njoints) if model.joints[j].shortname().startswith(("JointModelR",))
    ]
    joints = tuple(joints or revolute)
    pots = [
        {
            "name": f"{j}_pot",
            "kind": "rotary",
            "joint": j,
            "gain": float(rng.uniform(0.8, 1.2)),
            "bias": float(rng.uniform(-0.2, 0.2)),
        }
        for j in joints
    ]
    # the body frame whose parent joint is each joint (the link the joint moves)
    child = {}
    for f in model.frames:
        if f.type == pin.FrameType.BODY and f.parentJoint > 0:
            child.setdefault(model.names[f.parentJoint], f.name)
    links = [child[j] for j in joints if j in child]
    chosen = links[marker_every - 1 :: marker_every]
    if links and links[-1] not in chosen:
        chosen.append(links[-1])
    markers = [
        {"name": f"{link}_m{k}", "link": link, "xyz": [float(v) for v in rng.uniform(-0.05, 0.05, 3)]}
        for link in chosen
        for k in range(markers_per_link)
    ]
    sensors = {"urdf": "robot.urdf", "base_link": root, "pots": pots, "markers": markers}
    (out / "sensors.yaml").write_text(yaml.safe_dump(sensors, sort_keys=False))
    return out
