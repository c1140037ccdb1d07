"""URDF files: reading one (a plain ``.urdf`` or a xacro description), its joints, and editing.

:func:`urdf_text` expands a ``.xacro`` / ``.urdf.xacro`` description with the ``xacro`` package
(ROS's macro language for XML, usable without ROS); :func:`urdf_joints` lists each joint's type and
mimic relation (URDF ``<mimic joint= multiplier= offset=>``: q = multiplier · q_leader + offset).
:func:`reduce_urdf` freezes every joint but the ones a log moves: used by ``scripts/convert_real.py``
to build ``robots/tiago`` from the full TIAGo URDF (68 joints: casters, wheels, head, fingers)
with only the torso lift and the arm moving.
"""

from __future__ import annotations

import contextlib
import io
import logging
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from diegocal.errors import InputFileError
from diegocal.io.files import atomic_path

log = logging.getLogger(__name__)
XACRO_SUFFIXES = (".xacro",)  # robot.xacro, robot.urdf.xacro


def is_xacro(path) -> bool:
    return Path(path).suffix.lower() in XACRO_SUFFIXES


def urdf_text(path) -> str:
    """The URDF XML of ``path``: the file itself, or a xacro description expanded (its default args).

    Raises InputFileError (one line) for a missing file or a xacro that cannot be expanded, e.g. one
    that includes ROS packages with ``$(find pkg)`` (expand it in a ROS environment instead).
    """
    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"{path}: no such file")
    if not is_xacro(path):
        return path.read_text()
    try:
        import xacro  # lazy: an optional package, and it loads scipy.spatial
    except ImportError:  # pragma: no cover - a runtime dependency
        raise InputFileError(f"{path}: reading xacro needs the xacro package (pip install xacro)") from None
    chatter = io.StringIO()
    try:
        with contextlib.redirect_stderr(chatter):  # xacro prints its warnings on stderr
            text = xacro.process_file(str(path)).toxml()
    except Exception as exc:  # noqa: BLE001 - xacro raises XacroException, expat and name errors
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0].strip()
        hint = ("; $(find ...) needs ROS: run `xacro` where the packages are installed and give the .urdf"
                if "substitution args" in first or "$(find" in first else "")
        raise InputFileError(f"{path}: xacro cannot expand it ({first}){hint}") from None
    for line in chatter.getvalue().splitlines():
        if line.strip():
            log.debug("xacro: %s", line.strip())
    return text


@dataclass(frozen=True)
class UrdfJoint:
    """One ``<joint>`` of a URDF: its type and, for a mimic joint, q = multiplier · q_leader + offset."""

    name: str
    kind: str
    leader: str | None = None
    multiplier: float = 1.0
    offset: float = 0.0


def urdf_joints(path) -> dict[str, UrdfJoint]:
    """Every joint of the URDF (or xacro) at ``path`` by name, in file order."""
    try:
        root = ET.fromstring(urdf_text(path))
    except ET.ParseError as exc:
        raise InputFileError(f"{path}: not valid XML ({exc})") from None
    out = {}
    for joint in root.iter("joint"):
        if joint.get("name") is None or joint.get("type") is None:
            continue  # a <transmission>'s <joint> reference
        mimic = joint.find("mimic")
        out[joint.get("name")] = UrdfJoint(
            joint.get("name"), joint.get("type"),
            leader=None if mimic is None else mimic.get("joint"),
            multiplier=1.0 if mimic is None else float(mimic.get("multiplier", 1.0)),
            offset=0.0 if mimic is None else float(mimic.get("offset", 0.0)))
    return out


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
