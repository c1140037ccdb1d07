"""Any URDF Pinocchio loads, reduced to the joints the sensors and the data use (DESIGN.md,
"Robot directory").

The observation models and the dynamics work on one-DoF joints (revolute, prismatic: q and qd of
the same size). A real URDF has more: continuous wheels and casters (Pinocchio's ``RUB`` joints,
two position coordinates cos/sin per angle), mimic joints, a floating or planar base. Two steps
turn it into a model diegocal can use:

0. **A xacro description** (``.xacro``, ``.urdf.xacro``) is expanded first (:func:`diegocal.io.urdf.urdf_text`).
1. **Continuous joints become revolute** with limits ±π (:data:`CONTINUOUS_LIMIT`): the URDF's
   XML is edited (``type="continuous"`` → ``"revolute"``, a ``<limit>`` with lower/upper ±π, its
   effort and velocity kept) before Pinocchio parses it, so the joint keeps its axis, origin,
   inertia and name and gets one coordinate, the angle. Mimic joints are loaded as independent
   joints (Pinocchio's ``mimic=False``): one the data use is tracked on its own; one they do not is
   locked like any other.
2. **Unused joints are locked** (Pinocchio's :func:`pinocchio.buildReducedModel`): every joint
   that neither a sensor in sensors.yaml nor a joint stream of the log uses is removed, its child
   link fixed to its parent at the *locked configuration*: the value sensors.yaml gives under
   ``locked: {joint: value}`` (a list of the joint's position coordinates for a multi-DoF joint),
   else 0 clipped into the joint's limits (Pinocchio's neutral configuration for multi-DoF joints:
   identity for a free-flyer). The locked links' inertias are merged into the link that carries
   them, so the reduced model's dynamics are those of the robot with those joints held still.

What "used" means is :func:`sensor_joints`: joints a pot reads, joints that move a marker or a
linear pot's anchor relative to the base link, chamber joints. When neither the sensors nor the
data name any joint (a URDF for dynamics, simulated without a log) every one-DoF joint is kept and
only multi-DoF joints (free-flyer, planar, spherical) are locked. A multi-DoF joint that is used
is an error: it names the joint and how to lock it.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin

from diegocal.errors import InputFileError, RobotConfigError
from diegocal.io.urdf import is_xacro, urdf_text

#: Limits (rad) given to a continuous joint turned revolute: one full turn around zero.
CONTINUOUS_LIMIT = np.pi


@dataclass(frozen=True)
class LoadedUrdf:
    """A URDF as Pinocchio loaded it, continuous joints already revolute.

    model : pinocchio.Model (every joint of the URDF)
    continuous : names of the joints that were continuous in the URDF
    mimic : {mimic joint: (leader, multiplier, offset)}, q = multiplier · q_leader + offset
    """

    model: pin.Model
    continuous: tuple[str, ...]
    mimic: dict = field(default_factory=dict)


def load_urdf(path) -> LoadedUrdf:
    """Parse a URDF (or a xacro description) with Pinocchio after turning continuous joints into
    revolute ones (±π).

    Raises RobotConfigError (one line) when the file is not XML, xacro cannot expand it or
    Pinocchio refuses it.
    """
    path = Path(path)
    try:
        root = ET.fromstring(urdf_text(path))
    except InputFileError as exc:
        raise RobotConfigError(str(exc)) from None
    except ET.ParseError as exc:
        raise RobotConfigError(f"{path}: Pinocchio cannot load it (not valid XML: {exc})") from None
    continuous = []
    for joint in root.iter("joint"):
        if joint.get("type") == "continuous":
            joint.set("type", "revolute")
            limit = joint.find("limit")
            if limit is None:
                limit = ET.SubElement(joint, "limit", {"effort": "0", "velocity": "0"})
            limit.set("lower", repr(-CONTINUOUS_LIMIT))
            limit.set("upper", repr(CONTINUOUS_LIMIT))
            limit.attrib.setdefault("effort", "0")
            limit.attrib.setdefault("velocity", "0")
            continuous.append(joint.get("name"))
    mimic = {j.get("name"): (m.get("joint"), float(m.get("multiplier", 1.0)), float(m.get("offset", 0.0)))
             for j in root.iter("joint") if (m := j.find("mimic")) is not None}
    text = ET.tostring(root, encoding="unicode")
    try:
        model = (pin.buildModelFromXML(text) if continuous or is_xacro(path)
                 else pin.buildModelFromUrdf(str(path)))
    except (RuntimeError, ValueError) as exc:
        raise RobotConfigError(f"{path}: Pinocchio cannot load it ({str(exc).splitlines()[0]})") from None
    return LoadedUrdf(model, tuple(continuous), mimic)


def is_one_dof(model: pin.Model, j: int) -> bool:
    return model.joints[j].nq == 1 and model.joints[j].nv == 1


def joint_kind(model: pin.Model, j: int) -> str:
    """A short readable name of joint ``j``'s type: revolute, prismatic, free-flyer, planar, ..."""
    short = model.joints[j].shortname().replace("JointModel", "")
    if short.startswith(("RevoluteUnaligned", "RX", "RY", "RZ")):
        return "revolute"
    if short.startswith(("Prismatic", "PX", "PY", "PZ")):
        return "prismatic"
    return {"FreeFlyer": "free-flyer", "Planar": "planar", "Spherical": "spherical"}.get(short, short)


@dataclass(frozen=True)
class Reduction:
    """The reduced model and what was locked: ``locked`` maps each locked joint's name to its
    configuration (a float for a one-DoF joint, a list of its position coordinates otherwise)."""

    model: pin.Model
    locked: dict


def reduce_model(model: pin.Model, keep, locked_values: dict | None = None) -> Reduction:
    """Lock every joint not in ``keep`` (None: keep every one-DoF joint) and every joint named in
    ``locked_values`` at that configuration (see the module docstring); Pinocchio's
    ``buildReducedModel`` does the rest.

    Raises RobotConfigError when a kept joint has more than one DoF, or a locked value has the
    wrong size or names no joint.
    """
    locked_values = dict(locked_values or {})
    names = list(model.names)
    for name in locked_values:
        if name not in names[1:]:
            raise RobotConfigError(f"sensors.yaml: locked joint {name!r} is not a joint of the URDF")
    keep = None if keep is None else set(keep)
    q_ref = pin.neutral(model)
    lock_ids, locked = [], {}
    for j in range(1, model.njoints):
        name = names[j]
        kept = (is_one_dof(model, j) if keep is None else name in keep) and name not in locked_values
        if kept:
            if not is_one_dof(model, j):
                raise RobotConfigError(
                    f"joint {name!r} is a {joint_kind(model, j)} joint and the sensors or the log use it; "
                    "diegocal tracks one-DoF joints only: choose a base_link below it or lock it "
                    f"(sensors.yaml: locked: {{{name}: [...]}})"
                )
            continue
        jm = model.joints[j]
        sl = slice(jm.idx_q, jm.idx_q + jm.nq)
        if name in locked_values:
            value = np.atleast_1d(np.asarray(locked_values[name], dtype=float))
            if value.shape != (jm.nq,) or not np.isfinite(value).all():
                raise RobotConfigError(
                    f"sensors.yaml: locked joint {name!r} needs {jm.nq} finite number(s), got {locked_values[name]!r}"
                )
            q_ref[sl] = value
        elif jm.nq == 1:
            q_ref[sl] = np.clip(0.0, model.lowerPositionLimit[sl], model.upperPositionLimit[sl])
        lock_ids.append(j)
        locked[name] = float(q_ref[sl][0]) if jm.nq == 1 else [float(v) for v in q_ref[sl]]
    if not lock_ids:
        return Reduction(model, {})
    reduced = pin.buildReducedModel(model, lock_ids, q_ref)
    reduced.name = model.name
    return Reduction(reduced, locked)


def sensor_joints(model: pin.Model, sensors) -> set[str]:
    """Joints the sensors use: read by a pot, moving a marker or a linear pot's anchor relative to
    ``sensors.base_link``, or driven by a chamber. Unknown names are skipped here (the Robot's
    own checks name them)."""
    used = set()
    for p in sensors.pots:
        used.update(p.joints)
    links = [m.link for m in sensors.markers]
    links += [a.link for p in sensors.pots if p.kind == "linear" for a in p.anchors]
    if links and model.existFrame(sensors.base_link):
        base = _support(model, sensors.base_link)
        for link in links:
            if model.existFrame(link):
                chain = _support(model, link)
                used.update(model.names[k] for k in chain ^ base if k > 0)  # moves it relative to the base
    for c in sensors.chambers:
        used.add(c.joint)
        used.add(c.volume_sensor)  # a joint name when the volume is read from q (else no joint)
    return used


def _support(model: pin.Model, link: str) -> set[int]:
    """Joint ids from the root to the joint carrying ``link`` (its body frame when one exists)."""
    body = model.existFrame(link, pin.FrameType.BODY)
    fid = model.getFrameId(link, pin.FrameType.BODY) if body else model.getFrameId(link)
    return set(model.supports[model.frames[fid].parentJoint])


def root_link(model: pin.Model) -> str:
    """The URDF's root link: the first body frame."""
    return next(f.name for f in model.frames if f.type == pin.FrameType.BODY)
