"""Fitted-model bundles: one header, one loader for every fitted output (DESIGN.md, "Command line").

Every fitted output records the same header at its top level::

    kind: calibration | pneumatic | dynamics | diagnosis
    robot: {name: diego, dir: /abs/robots/diego, hash: sha256:…}   # hash of robot.urdf + sensors.yaml
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
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

from diegocal.errors import InputFileError
from diegocal.io.files import load_yaml

KINDS = ("calibration", "pneumatic", "dynamics", "diagnosis")
#: The file inside a dynamics bundle's directory that holds its header and summary.
DYNAMICS_SUMMARY = "sgp.yaml"
#: Header keys, in the order they are written.
HEADER_KEYS = ("kind", "robot", "log", "command", "version", "created")


def robot_hash(directory) -> str | None:
    """``sha256:<hex>`` of a robot directory's URDF and sensors.yaml (None if it has neither).

    The URDF is the one sensors.yaml names (default ``robot.urdf``); the bytes are hashed as
    they are on disk, so any edit, even of a comment, gives another robot.
    """
    directory = Path(directory)
    sensors = directory / "sensors.yaml"
    urdf_name = "robot.urdf"
    if sensors.is_file():
        try:
            urdf_name = str((load_yaml(sensors) or {}).get("urdf", urdf_name))
        except InputFileError:
            pass
    h = hashlib.sha256()
    found = False
    for path in (directory / urdf_name, sensors):
        if path.is_file():
            h.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
            found = True
    return f"sha256:{h.hexdigest()}" if found else None


def robot_record(robot) -> dict:
    """``{name, dir, hash}`` of a :class:`diegocal.robot.Robot` (dir and hash None without a directory)."""
    directory = getattr(robot, "directory", None)
    return {
        "name": str(robot.name),
        "dir": None if directory is None else str(Path(directory).resolve()),
        "hash": None if directory is None else robot_hash(directory),
    }


def header(kind: str, robot=None, log=None, command: str | None = None) -> dict:
    """The bundle header of a new fitted output (see the module docstring).

    ``robot`` is a Robot (or None), ``log`` the path of the log it was fitted on (or None).
    """
    from diegocal import __version__

    if kind not in KINDS:
        raise ValueError(f"unknown bundle kind {kind!r}; expected one of {', '.join(KINDS)}")
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
        """``{name, dir, hash}`` (None values where the file does not say; legacy files may
        give only a name or a directory in ``meta.robot``)."""
        rec = self.data.get("robot")
        if isinstance(rec, dict):
            return {"name": rec.get("name"), "dir": rec.get("dir"), "hash": rec.get("hash")}
        legacy = (self.data.get("meta") or {}).get("robot")
        text = rec if isinstance(rec, str) else legacy if isinstance(legacy, str) else None
        if text is None:
            return {"name": None, "dir": None, "hash": None}
        is_dir = "/" in text
        return {"name": Path(text).name if is_dir else text, "dir": text if is_dir else None, "hash": None}

    @property
    def log(self) -> str | None:
        return self.data.get("log") or (self.data.get("meta") or {}).get("log")


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
    if "chambers" in data:
        return Bundle("pneumatic", path, data)
    if {"pots", "markers", "mocap"} & set(data):
        return Bundle("calibration", path, data)
    if "findings" in data and "domain" in data:
        return Bundle("diagnosis", path, data)
    raise InputFileError(
        f"{path}: not a fitted diegocal model (calib.yaml, pneumatic.yaml, a dynamics directory or diagnosis.yaml)"
    )
