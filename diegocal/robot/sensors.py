"""``sensors.yaml``: the robot's pots, markers and chambers with their nominal parameters.

The schema is DESIGN.md's ("Robot directory"). Each entry is validated on load and an error
names the bad entry: ``sensors.yaml: pots[3] (neck_a): linear pot needs two anchors``.
Nominal ``gain``/``bias``/``xyz`` are seeds for calibration, not truths.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from diegocal.errors import RobotConfigError

POT_KINDS = ("rotary", "linear", "tendon", "encoder")


@dataclass(frozen=True)
class Anchor:
    """A point fixed on a link: ``xyz`` (3,) in metres, in the link frame."""

    link: str
    xyz: np.ndarray


@dataclass(frozen=True)
class PotSpec:
    """A sensor whose reading is a function of joint angles: p = gain · s(q) + bias.

    ``s(q)`` is the transmission quantity: the joint angle (rotary, encoder; thesis eq. 2.18),
    the distance between two anchors (linear; eq. 2.19-2.20) or the weighted sum of joint
    angles (tendon; moment arms in metres, so s is a length, §2.3.3).
    """

    name: str
    kind: str
    gain: float
    bias: float
    joint: str | None = None
    anchors: tuple[Anchor, Anchor] | None = None
    moment_arms: dict = field(default_factory=dict)

    @property
    def joints(self) -> tuple[str, ...]:
        """Joints this sensor reads directly (empty for linear pots: they depend on geometry)."""
        if self.kind in ("rotary", "encoder"):
            return (self.joint,)
        if self.kind == "tendon":
            return tuple(self.moment_arms)
        return ()


@dataclass(frozen=True)
class MarkerSpec:
    """A motion-capture marker: nominal position ``xyz`` (3,) in metres in frame ``link``."""

    name: str
    link: str
    xyz: np.ndarray


@dataclass(frozen=True)
class ChamberSpec:
    """A pneumatic valve-chamber system (thesis ch. 4).

    ``supply``/``room`` are absolute pressures in the pressure stream's unit; ``extra`` keeps
    any further keys (cylinder geometry, valve constants) for the pneumatic code to read.
    """

    name: str
    joint: str
    volume_sensor: str
    supply: float
    room: float
    extra: dict = field(default_factory=dict)


@dataclass(frozen=True)
class SensorConfig:
    """The parsed sensors.yaml. ``locked`` maps joints to hold still to their configuration (a
    number, or a list of position coordinates for a multi-DoF joint; see :mod:`.urdf`)."""

    urdf: str
    base_link: str
    pots: tuple[PotSpec, ...]
    markers: tuple[MarkerSpec, ...]
    chambers: tuple[ChamberSpec, ...]
    locked: dict = field(default_factory=dict)

    @property
    def pot_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.pots)

    @property
    def marker_names(self) -> tuple[str, ...]:
        return tuple(m.name for m in self.markers)

    @property
    def chamber_names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.chambers)


def parse_sensors(raw: dict, source: str = "sensors.yaml") -> SensorConfig:
    """Validate the parsed YAML mapping and build a :class:`SensorConfig`."""
    if not isinstance(raw, dict):
        raise RobotConfigError(f"{source}: expected a mapping at the top level")
    urdf = raw.get("urdf", "robot.urdf")
    base = raw.get("base_link")
    if not isinstance(base, str) or not base:
        raise RobotConfigError(
            f"{source}: 'base_link' (the link the mocap frame is fixed to) is required"
        )
    pots = tuple(_parse_list(raw, "pots", _parse_pot, source))
    markers = tuple(_parse_list(raw, "markers", _parse_marker, source))
    chambers = tuple(_parse_list(raw, "chambers", _parse_chamber, source))
    return SensorConfig(str(urdf), base, pots, markers, chambers, _parse_locked(raw.get("locked"), source))


def _parse_locked(raw, source: str) -> dict:
    """``locked: {joint: value | [values]}``: joints held still (see :mod:`diegocal.robot.urdf`)."""
    if raw is None:
        return {}
    if not isinstance(raw, dict):
        raise RobotConfigError(f"{source}: 'locked' must be a mapping {{joint: value}}")
    out = {}
    for joint, value in raw.items():
        values = value if isinstance(value, list) else [value]
        try:
            arr = np.asarray(values, dtype=float)
        except (TypeError, ValueError):
            arr = np.array([np.nan])
        if arr.ndim != 1 or not arr.size or not np.isfinite(arr).all():
            raise RobotConfigError(f"{source}: locked[{joint}] must be a number or a list of numbers, got {value!r}")
        out[str(joint)] = float(arr[0]) if not isinstance(value, list) else [float(v) for v in arr]
    return out


def _parse_list(raw, key, parse, source):
    entries = raw.get(key) or []
    if not isinstance(entries, list):
        raise RobotConfigError(f"{source}: '{key}' must be a list")
    seen = set()
    out = []
    for i, entry in enumerate(entries):
        label = f"{source}: {key}[{i}]"
        if not isinstance(entry, dict):
            raise RobotConfigError(f"{label}: expected a mapping, got {type(entry).__name__}")
        name = entry.get("name")
        if not isinstance(name, str) or not name:
            raise RobotConfigError(f"{label}: missing 'name'")
        label = f"{label} ({name})"
        if name in seen:
            raise RobotConfigError(f"{label}: duplicate name")
        seen.add(name)
        try:
            out.append(parse(entry, label))
        except (TypeError, ValueError) as exc:
            if isinstance(exc, RobotConfigError):
                raise
            raise RobotConfigError(f"{label}: {exc}") from None
    return out


def _number(entry, key, label, default=None) -> float:
    value = entry.get(key, default)
    if value is None:
        raise RobotConfigError(f"{label}: missing '{key}'")
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise RobotConfigError(f"{label}: '{key}' must be a number, got {value!r}") from None
    if not np.isfinite(value):
        raise RobotConfigError(f"{label}: '{key}' must be finite")
    return value


def _xyz(value, label, what="xyz") -> np.ndarray:
    arr = np.asarray(value if value is not None else [0.0, 0.0, 0.0], dtype=float)
    if arr.shape != (3,) or not np.isfinite(arr).all():
        raise RobotConfigError(f"{label}: '{what}' must be three finite numbers, got {value!r}")
    return arr


def _parse_pot(entry, label) -> PotSpec:
    kind = entry.get("kind")
    if kind not in POT_KINDS:
        raise RobotConfigError(
            f"{label}: unknown kind {kind!r} (expected one of {', '.join(POT_KINDS)})"
        )
    bias = _number(entry, "bias", label, 0.0)
    if kind == "encoder":
        if "gain" in entry and _number(entry, "gain", label) != 1.0:
            raise RobotConfigError(f"{label}: an encoder's gain is fixed at 1")
        gain = 1.0
    else:
        gain = _number(entry, "gain", label, 1.0)
        if gain == 0.0:
            raise RobotConfigError(f"{label}: gain must be non-zero")
    if kind in ("rotary", "encoder"):
        joint = entry.get("joint")
        if not isinstance(joint, str) or not joint:
            raise RobotConfigError(f"{label}: {kind} pot needs 'joint'")
        return PotSpec(entry["name"], kind, gain, bias, joint=joint)
    if kind == "linear":
        anchors = entry.get("anchors")
        if not isinstance(anchors, list) or len(anchors) != 2:
            raise RobotConfigError(
                f"{label}: linear pot needs two anchors [{{link, xyz}}, {{link, xyz}}]"
            )
        parsed = []
        for j, a in enumerate(anchors):
            if not isinstance(a, dict) or not isinstance(a.get("link"), str):
                raise RobotConfigError(f"{label}: anchors[{j}] needs 'link'")
            parsed.append(Anchor(a["link"], _xyz(a.get("xyz"), label, f"anchors[{j}].xyz")))
        if parsed[0].link == parsed[1].link:
            raise RobotConfigError(
                f"{label}: both anchors are on link {parsed[0].link!r}; the length never changes"
            )
        return PotSpec(entry["name"], kind, gain, bias, anchors=tuple(parsed))
    arms = entry.get("moment_arms")
    if not isinstance(arms, dict) or not arms:
        raise RobotConfigError(f"{label}: tendon needs 'moment_arms: {{joint: metres, ...}}'")
    arms = {str(j): _number(arms, j, label) for j in arms}
    return PotSpec(entry["name"], kind, gain, bias, moment_arms=arms)


def _parse_marker(entry, label) -> MarkerSpec:
    link = entry.get("link")
    if not isinstance(link, str) or not link:
        raise RobotConfigError(f"{label}: marker needs 'link'")
    return MarkerSpec(entry["name"], link, _xyz(entry.get("xyz"), label))


def _parse_chamber(entry, label) -> ChamberSpec:
    joint = entry.get("joint")
    if not isinstance(joint, str) or not joint:
        raise RobotConfigError(f"{label}: chamber needs 'joint'")
    volume = entry.get("volume_sensor", joint)
    supply = _number(entry, "supply", label)
    room = _number(entry, "room", label)
    if not supply > room > 0:
        raise RobotConfigError(f"{label}: need supply > room > 0, got supply={supply}, room={room}")
    known = {"name", "joint", "volume_sensor", "supply", "room"}
    extra = {k: v for k, v in entry.items() if k not in known}
    return ChamberSpec(entry["name"], joint, str(volume), supply, room, extra)
