"""What an import checks against the robot a log is for (``--robot`` or the map's ``robot``).

The robot is a bundled name, a robot directory (sensors.yaml + its URDF), a URDF file or a xacro
description (``.xacro``, ``.urdf.xacro``, expanded with the ``xacro`` package). From it the import
takes three things, read from the XML (no dynamics model is built):

- each joint's type: a prismatic joint's q is in m and its tau in N (a revolute's rad and N·m);
  a unit of the wrong family is an error, and the summary names the unit per joint;
- mimic joints (URDF ``<mimic>``, q_f = m · q_l + o): a gripper finger driven by its partner has
  one coordinate, the leader's. Its q, qd, qdd channels are dropped (checked against the leader's)
  and its effort is added to the leader's as m · τ_f (virtual work: δW = τ_l δq_l + τ_f m δq_l);
- the marker names of sensors.yaml: a marker the robot does not name is reported with the
  closest names it does.

A robot that cannot be found is a warning (the log still names it), not an error.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from diegocal.io.importers.units import JOINT_UNIT, LOG_UNIT, close_match
from diegocal.io.log import JOINT_STREAMS, make_stream
from diegocal.io.urdf import UrdfJoint, is_xacro, urdf_joints

log = logging.getLogger(__name__)

#: Largest difference (rad or m) between a mimic joint's reading and m · leader + o that is still
#: taken as the URDF's relation (encoder resolution, two drivers' rounding).
MIMIC_TOLERANCE = 1e-3


@dataclass(frozen=True)
class RobotInfo:
    """The robot's joints (URDF order) and its sensors.yaml marker names (empty without one)."""

    name: str
    joints: dict[str, UrdfJoint]
    markers: tuple[str, ...] = ()

    def kind(self, joint: str) -> str | None:
        j = self.joints.get(joint)
        return None if j is None else j.kind

    @property
    def mimic(self) -> dict[str, UrdfJoint]:
        return {n: j for n, j in self.joints.items() if j.leader is not None}


def robot_info(robot: str | None) -> RobotInfo | None:
    """The robot named by ``robot``; None (with a warning when one was named) if it cannot be found."""
    if not robot:
        return None
    urdf, sensors = _locate(str(robot))
    if urdf is None:
        log.warning("robot %r not found (no such directory, URDF, xacro or bundled robot): joint units and marker "
                    "names are not checked", robot)
        return None
    markers = ()
    if sensors is not None:
        from diegocal.io.files import load_yaml

        raw = load_yaml(sensors) or {}
        markers = tuple(str(m.get("name")) for m in raw.get("markers", []) or [] if isinstance(m, dict))
    return RobotInfo(str(robot), urdf_joints(urdf), markers)


def robot_attribute(robot: str | None) -> str | None:
    """What the log's ``robot`` attribute holds: a robot given as a path that exists, made absolute
    (the log is then read the same from any folder); a bundled name, or a path not found, as given."""
    if not robot:
        return robot
    path = Path(robot)
    if path.exists() and ("/" in str(robot) or path.suffix or path.is_dir()):
        return str(path.resolve())
    return robot


def _locate(robot: str) -> tuple[Path | None, Path | None]:
    """(URDF or xacro file, sensors.yaml or None) of a robot given as a path or a bundled name."""
    path = Path(robot)
    if path.is_file() and (path.suffix.lower() == ".urdf" or is_xacro(path)):
        return path, None
    if not path.is_dir() and "/" not in robot:
        from diegocal.robot.model import BUNDLED_ROBOTS

        path = BUNDLED_ROBOTS / robot
    if not path.is_dir():
        return None, None
    sensors = path / "sensors.yaml"
    if sensors.is_file():
        from diegocal.io.files import load_yaml

        urdf = path / str((load_yaml(sensors) or {}).get("urdf", "robot.urdf"))
        return (urdf if urdf.is_file() else None), sensors
    urdf = path / "robot.urdf"
    return (urdf if urdf.is_file() else None), None


def unit_text(stream: str, names, info: RobotInfo | None) -> str:
    """The log's unit of a joint stream's channels in words: 'N·m', 'N', or 'N·m; N for a (prismatic)'."""
    if info is None or stream not in JOINT_UNIT:
        return LOG_UNIT[stream]
    angular, linear = JOINT_UNIT[stream]
    names = [n for n in names if n not in info.mimic]  # folded into their leaders (fold_mimic)
    prismatic = [n for n in names if info.kind(n) == "prismatic"]
    if not prismatic:
        return angular
    if len(prismatic) == len(names):
        return linear
    return f"{angular}; {linear} for {', '.join(prismatic)} (prismatic)"


def fold_mimic(streams: dict, info: RobotInfo | None, notes: list[str]) -> dict:
    """Joint streams with one coordinate per mimic pair: the leader's (see the module docstring)."""
    if info is None:
        return streams
    out = dict(streams)
    for follower, j in info.mimic.items():
        present = [s for s in JOINT_STREAMS if s in out and follower in out[s].names]
        if not present and not any(s in out and j.leader in out[s].names for s in JOINT_STREAMS):
            continue
        for s in present:
            out[s] = _fold(s, out[s], follower, j)
        what = f"its {', '.join(present)} folded into {j.leader}'s" if present else "no channel of its own"
        notes.append(f"mimic: {follower} = {j.multiplier:g} × {j.leader} {j.offset:+g}, driven from {j.leader} "
                     f"(one coordinate; {what})")
    return out


def _fold(stream: str, st, follower: str, j: UrdfJoint):
    names = list(st.names)
    data = st.data.copy()
    f = names.index(follower)
    # position: q_f = m q_l + o; velocity, acceleration: m times the leader's; effort: τ_l += m τ_f
    offset = j.offset if stream == "q" else 0.0
    if j.leader in names:
        lead = names.index(j.leader)
        if stream == "tau":
            data[:, lead] = data[:, lead] + j.multiplier * data[:, f]
        elif stream == "q":
            gap = float(np.max(np.abs(data[:, f] - (j.multiplier * data[:, lead] + offset))))
            if gap > MIMIC_TOLERANCE:
                log.warning("q of %s departs from the URDF's mimic of %s by up to %.3g rad (m); %s's kept",
                            follower, j.leader, gap, j.leader)
    else:  # only the follower was recorded: the leader's coordinate from it
        names[f] = j.leader
        data[:, f] = j.multiplier * data[:, f] if stream == "tau" else (data[:, f] - offset) / j.multiplier
        return make_stream(names, data)
    keep = [k for k in range(len(names)) if k != f]
    return make_stream([names[k] for k in keep], data[:, keep])


def check_marker_names(names, info: RobotInfo | None) -> None:
    """Warn, with the closest names, about markers the robot's sensors.yaml does not name."""
    if info is None or not info.markers:
        return
    unknown = [n for n in names if n not in info.markers]
    if unknown:
        hints = "; ".join(f"{n}{close_match(n, info.markers)}" for n in unknown[:6])
        log.warning("%d marker(s) not in %s's sensors.yaml: %s%s (map them with `columns:` on the markers stream)",
                    len(unknown), info.name, hints, ", ..." if len(unknown) > 6 else "")
