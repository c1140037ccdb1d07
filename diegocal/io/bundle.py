"""Fitted-model bundles: one header, one loader for every fitted output (DESIGN.md, "Command line").

Every fitted output records the same header at its top level::

    kind: kinematics | dynamics | pneumatics | diagnosis   # (layout 1: calibration, pneumatic)
    robot: {name: diego, dir: /abs/robots/diego, hash: sha256:…}   # hash of robot.urdf + sensors.yaml
                                     # (+ locked: {joint: value} when its model was reduced)
    log: /abs/path/run.h5            # the log it was fitted on
    command: diegocal stac run.h5
    version: 0.1.0                   # diegocal's
    created: 2026-11-24T10:00:00+00:00

A calibration (calib.yaml) and a pneumatic model (pneumatic.yaml) are YAML files; a dynamics
model is a directory (``sgp.yaml`` holds the header, ``model.npz`` the arrays); a diagnosis is
``diagnosis.yaml`` (its extended model is a bundle of its domain's kind). :func:`load_bundle` reads
any of them and says which kind it is, so that ``predict``, ``report`` and ``diagnose`` dispatch on
``kind``, never on file names. Files written before the header existed are still recognised by
their shape (``pots``/``markers``/``mocap``: a calibration; ``chambers``: a pneumatic model;
a directory with ``sgp.yaml``: a dynamics model).
"""

from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

from diegocal import __version__
from diegocal.domains import domain
from diegocal.errors import InputFileError
from diegocal.io.files import load_yaml, save_yaml, write_text

KINDS = ("kinematics", "dynamics", "pneumatics", "diagnosis")
#: The file inside a dynamics bundle's directory that holds its header and summary.
DYNAMICS_SUMMARY = "sgp.yaml"
#: The file layout diegocal writes: 2 writes every fitted parameter as ``{value, stderr, unit}``
#: under a term's ``parameters`` (:mod:`diegocal.terms`); files without ``layout`` are layout 1.
LAYOUT = 2
#: Header keys, in the order they are written.
HEADER_KEYS = ("kind", "robot", "log", "command", "version", "created")


def robot_hash(source) -> str | None:
    """``sha256:<hex>`` of a robot's URDF and sensors.yaml (None if it has neither).

    ``source`` is a robot directory (the URDF is the one sensors.yaml names, default
    ``robot.urdf``) or a URDF file (dynamics alone: the file only). The bytes are hashed as they
    are on disk, so any edit, even of a comment, gives another robot. A xacro description is
    hashed as the URDF it expands to (:func:`diegocal.io.urdf.urdf_text`) less its comments
    (xacro's banner names the file's absolute path, which must not make a moved robot another
    one), so that an edit of a file it includes, which its own bytes do not show, gives another
    robot too; one it cannot expand is hashed as its bytes.
    """
    source = Path(source)
    if source.is_file():
        paths = (source,)
    else:
        sensors = source / "sensors.yaml"
        urdf_name = "robot.urdf"
        if sensors.is_file():
            try:
                urdf_name = str((load_yaml(sensors) or {}).get("urdf", urdf_name))
            except InputFileError:
                pass
        paths = (source / urdf_name, sensors)
    h = hashlib.sha256()
    found = False
    for path in paths:
        if path.is_file():
            h.update(path.name.encode() + b"\0" + _described(path) + b"\0")
            found = True
    return f"sha256:{h.hexdigest()}" if found else None


def _described(path: Path) -> bytes:
    """The bytes that describe the robot in ``path``: a xacro's expansion, any other file itself."""
    # lazy: io.urdf loads scipy.spatial (most of a second): not at import, which every bundle reader does
    from diegocal.io.urdf import is_xacro, urdf_text

    if is_xacro(path):
        try:
            return re.sub(r"<!--.*?-->", "", urdf_text(path), flags=re.DOTALL).encode()
        except InputFileError:
            pass
    return path.read_bytes()


def robot_record(robot) -> dict:
    """``{name, dir, hash}`` of a :class:`diegocal.robot.Robot` (dir and hash None when it was not
    loaded from disk; ``dir`` is the URDF file for a robot given as a URDF), plus ``locked`` (the
    joints held still in its reduced model) when there are any."""
    source = getattr(robot, "source", None) or getattr(robot, "directory", None)
    out = {
        "name": str(robot.name),
        "dir": None if source is None else str(Path(source).resolve()),
        "hash": None if source is None else robot_hash(source),
    }
    if getattr(robot, "locked", None):
        out["locked"] = dict(robot.locked)
    return out


def same_robot(record: dict, source) -> bool:
    """Whether the robot at ``source`` (directory or URDF) has the files a bundle's robot record
    hashed (True when the record has no hash: files written before hashes existed)."""
    return not record.get("hash") or robot_hash(source) == record["hash"]


def save_robot_copy(robot, directory) -> None:
    """Write a self-contained copy of ``robot`` into ``directory``: ``robot.urdf`` (a xacro
    description expanded: the copy needs neither xacro nor the files it includes) and a
    ``sensors.yaml`` (the original's, or a minimal one for a URDF-only robot) whose ``locked``
    lists every joint the robot's reduced model holds still, so that loading the copy rebuilds
    the same model whatever data it is used with."""
    from diegocal.io.urdf import urdf_text  # lazy: io.urdf loads scipy.spatial (see _described)

    directory = Path(directory)
    source = Path(getattr(robot, "source", None) or robot.directory)
    if source.is_dir() and not (source / "sensors.yaml").is_file():
        source = source / robot.sensors.urdf
    if source.is_file():
        urdf, sensors = source, {"urdf": "robot.urdf", "base_link": robot.sensors.base_link}
    else:
        urdf = source / robot.sensors.urdf
        sensors = dict(load_yaml(source / "sensors.yaml"))
    sensors["urdf"] = "robot.urdf"
    if getattr(robot, "locked", None):
        sensors["locked"] = dict(robot.locked)
    write_text(directory / "robot.urdf", urdf_text(urdf))
    save_yaml(sensors, directory / "sensors.yaml")


def header(kind: str, robot=None, log=None, command: str | None = None) -> dict:
    """The bundle header of a new fitted output (see the module docstring).

    ``robot`` is a Robot (or None), ``log`` the path of the log it was fitted on (or None).
    """
    if kind != "diagnosis":  # a domain's word (or an older one) -> the kind its models carry
        kind = domain(kind).kind
    return {
        "kind": kind,
        "robot": None if robot is None else robot_record(robot),
        "log": None if log is None else str(Path(log).resolve()),
        "command": command,
        "version": __version__,
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
    }


@dataclass(frozen=True)
class Bundle:
    """A fitted output as read from disk: its kind, where it is and its YAML mapping.

    ``data`` is the whole YAML mapping (for a dynamics model: its ``sgp.yaml``).
    """

    kind: str
    path: Path
    data: dict

    @property
    def robot(self) -> dict:
        """``{name, dir, hash}`` of the robot it was fitted for (:func:`robot_of`)."""
        return robot_of(self.data)

    @property
    def log(self) -> str | None:
        return self.data.get("log") or (self.data.get("meta") or {}).get("log")


def robot_of(data: dict) -> dict:
    """``{name, dir, hash}`` of a fitted output's mapping (None values where the file does not say;
    legacy files may give only a name or a directory in ``robot`` or ``meta.robot``)."""
    rec = data.get("robot")
    if isinstance(rec, dict):
        return {"name": rec.get("name"), "dir": rec.get("dir"), "hash": rec.get("hash")}
    legacy = (data.get("meta") or {}).get("robot")
    text = rec if isinstance(rec, str) else legacy if isinstance(legacy, str) else None
    if text is None:
        return {"name": None, "dir": None, "hash": None}
    is_dir = "/" in text
    return {"name": Path(text).name if is_dir else text, "dir": text if is_dir else None, "hash": None}


def bundle_kind(path) -> str:
    """The kind of the fitted output at ``path`` (:func:`load_bundle` without keeping the data)."""
    return load_bundle(path).kind


def load_bundle(path) -> Bundle:
    """Read any fitted output (calib.yaml, pneumatic.yaml, a dynamics directory, diagnosis.yaml).

    Raises InputFileError with one line when the path is missing or is no diegocal output.
    """
    path = Path(path)
    if not path.exists():
        raise InputFileError(f"{path}: no such model file or directory")
    if path.is_dir():
        summary = path / DYNAMICS_SUMMARY
        if not summary.is_file():
            raise InputFileError(f"{path}: a directory, but not a dynamics model (no {DYNAMICS_SUMMARY})")
        data = load_yaml(summary)
        return Bundle("dynamics", path, data if isinstance(data, dict) else {})
    data = load_yaml(path)
    if not isinstance(data, dict):
        raise InputFileError(f"{path}: not a fitted diegocal model (expected a YAML mapping)")
    kind = data.get("kind")
    if kind in KINDS:
        return Bundle(str(kind), path, data)
    if isinstance(kind, str) and kind in ("calibration", "pneumatic"):  # layout 1's words
        return Bundle(domain(kind).name, path, data)
    if "chambers" in data:
        return Bundle("pneumatics", path, data)
    if {"pots", "markers", "mocap"} & set(data):
        return Bundle("kinematics", path, data)
    if "findings" in data and "domain" in data:
        return Bundle("diagnosis", path, data)
    raise InputFileError(
        f"{path}: not a fitted diegocal model (calib.yaml, pneumatic.yaml, a dynamics directory or diagnosis.yaml)"
    )
