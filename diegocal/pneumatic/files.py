"""pneumatic.yaml: fitted chamber models plus what the report needs to rebuild its pages.

Schema (DESIGN.md; the bundle header of ``diegocal.io.bundle`` at the top, ``kind: pneumatic``;
files without it are recognised by their ``chambers`` key)::

    kind: pneumatic
    robot: {name, dir, hash}
    log: ...; command: ...; version: ...; created: ...
    chambers:
      r_elbow.flex: {c1..c9, c_b, c_s, c_gamma, v_ref, v_scale, stderr: {c1..c9},
                     terms: [{cause, channel, region, parameters: {name: {value, std, unit}}}],
                     cost, rmse, n_samples, drift_2s, drift_curve, volume_sensor, supply, room}
    meta: {command, log, robot, created, jacobian, starts, seed, skipped: {NAME: reason},
           drift: {starts, horizon_s, curve_step_s}, steady_state_log (optional)}

``terms`` (a chamber's extra terms, :mod:`diegocal.pneumatic.terms`) is there only when the
model has any (``diagnose`` writes them; ``predict`` and the report honour them).
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

from diegocal.errors import InputFileError
from diegocal.io import load_yaml
from diegocal.io.bundle import HEADER_KEYS
from diegocal.pneumatic.fit import BatchFit, FitOptions
from diegocal.pneumatic.params import ChamberParams
from diegocal.pneumatic.predict import CURVE_STEP_S
from diegocal.robot.sensors import SensorConfig


@dataclass(frozen=True)
class ChamberModel:
    """A fitted chamber as read back from pneumatic.yaml: its parameters and sensor facts."""

    name: str
    params: ChamberParams
    volume_sensor: str
    raw: dict


@dataclass(frozen=True)
class PneumaticModel:
    """The whole file: chambers by name (in file order) and ``meta``."""

    chambers: dict
    meta: dict


def model_dict(
    batch: BatchFit, sensors: SensorConfig, options: FitOptions, meta: dict, header: dict | None = None
) -> dict:
    """The pneumatic.yaml mapping for a batch of fits; ``meta`` adds log, robot, etc.;
    ``header`` (``diegocal.io.bundle.header("pneumatic", ...)``) goes first, at the top level."""
    specs = {c.name: c for c in sensors.chambers}
    chambers = {}
    for name, fit in batch.fits.items():
        entry = fit.to_dict()
        spec = specs[name]
        entry.update(volume_sensor=spec.volume_sensor, supply=spec.supply, room=spec.room)
        chambers[name] = entry
    head = {
        "command": "pneumatic-fit",
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
        "model": "thesis eq. (4.10), exact step (4.7); v normalised by v_ref, v_scale",
        "jacobian": options.jacobian,
        "starts": options.starts,
        "seed": options.seed,
        "drift": {
            "starts": options.drift_starts,
            "horizon_s": options.horizon_s,
            "curve_step_s": CURVE_STEP_S,
        },
        "skipped": dict(batch.skipped),
    }
    return {**(header or {}), "chambers": chambers, "meta": {**head, **meta}}


def parse_model(data: dict, source: str = "pneumatic.yaml") -> PneumaticModel:
    """Validate a loaded pneumatic.yaml mapping."""
    chambers = data.get("chambers")
    if not isinstance(chambers, dict) or not chambers:
        raise InputFileError(
            f"{source}: no fitted chambers (expected a non-empty 'chambers' mapping)"
        )
    out = {}
    for name, raw in chambers.items():
        where = f"{source}: chamber {name!r}"
        params = ChamberParams.from_dict(raw, where)
        sensor = raw.get("volume_sensor")
        if not isinstance(sensor, str):
            raise InputFileError(f"{where}: missing 'volume_sensor'")
        out[str(name)] = ChamberModel(str(name), params, sensor, raw)
    meta = data.get("meta") or {}
    return PneumaticModel(out, meta if isinstance(meta, dict) else {})


def load_model(path) -> PneumaticModel:
    return parse_model(load_yaml(path), str(path))


def merge_models(datas, sources) -> dict:
    """One pneumatic.yaml from several (the per-chamber files of ``make -j``).

    A chamber fitted in two files is an error (which one is right is not ours to guess); the
    merged ``meta`` keeps the first file's and lists every source; ``skipped`` entries are kept
    unless a later file fitted the chamber.
    """
    chambers, skipped, origin = {}, {}, {}
    meta = {}
    for data, src in zip(datas, sources, strict=True):
        model = parse_model(data, str(src))  # validates
        for name in model.chambers:
            if name in chambers:
                raise InputFileError(f"chamber {name!r} is fitted in both {origin[name]} and {src}")
            chambers[name] = data["chambers"][name]
            origin[name] = str(src)
        skipped.update(model.meta.get("skipped") or {})
        meta = meta or dict(model.meta)
    meta["skipped"] = {k: v for k, v in skipped.items() if k not in chambers}
    meta["merged_from"] = [str(Path(s)) for s in sources]
    first = datas[0] if datas else {}
    header = {k: first[k] for k in HEADER_KEYS if k in first}  # the first file's bundle header
    return {**header, "chambers": chambers, "meta": meta}
