"""C3D motion capture through ezc3d: marker trajectories (and analog channels) with their clocks.

Table ``points``: one (T, 3) column per ``POINT:LABELS`` entry (``LABELS2``... past 255), in
``POINT:UNITS`` (usually mm; converted to m when they become the ``markers`` stream), NaN where
the marker was not seen (ezc3d returns NaN for a negative residual, the C3D convention for an
invalid point). Time: (first frame + k) / ``POINT:RATE`` s. Table ``analogs`` (when the file
has any): one column per ``ANALOG:LABELS`` entry at ``ANALOG:RATE``, units from ``ANALOG:UNITS``;
ezc3d returns them already scaled (``SCALE``, ``GEN_SCALE``, ``OFFSET``).

A file cut short (a capture PC that crashed, a copy that stopped) is read by ezc3d without a word:
it quietly shrinks the frame count to what it found. The header's own first and last frame
(C3D header words 4 and 5, C3D.org "The C3D File Format User Guide", ch. 3) say how many frames
were written; fewer frames read is an error unless the source says ``allow_truncated: true``,
when the frames read are kept with a warning naming both counts.
"""

from __future__ import annotations

import logging
import struct
from pathlib import Path

import numpy as np

from diegocal.errors import LogFormatError
from diegocal.io.importers.mapping import SourceSpec
from diegocal.io.importers.tables import GENERIC, POINTS, Source, Table, finish_time

log = logging.getLogger(__name__)


def open_c3d(path: Path, spec: SourceSpec) -> Source:
    """A C3D source: tables ``points`` (the default) and ``analogs``."""
    tables = read_c3d(path, spec)
    return Source(spec=spec, path=path, kind="c3d", table_names=tuple(tables),
                  loader=tables.__getitem__, default_table="points")


def read_c3d(path: Path, spec: SourceSpec) -> dict[str, Table]:
    try:
        import ezc3d
    except ImportError:  # pragma: no cover - a runtime dependency
        raise LogFormatError("reading C3D files needs the ezc3d package (pip install ezc3d)") from None
    try:
        c3d = ezc3d.c3d(str(path))
    except Exception as exc:  # noqa: BLE001 - ezc3d raises RuntimeError/IOError for any bad file
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise LogFormatError(f"{path}: not a readable C3D file ({first})") from None
    params = c3d["parameters"]
    point = params.get("POINT", {})
    rate = _number(point, "RATE") or float(c3d["header"]["points"]["frame_rate"])
    if not rate > 0:
        raise LogFormatError(f"{path}: C3D has no POINT:RATE")
    first = int(c3d["header"]["points"]["first_frame"])
    points = np.asarray(c3d["data"]["points"], dtype=np.float64)  # (4, n, T)
    _check_complete(path, spec, points.shape[2], rate)
    labels = _labels(point, "LABELS", points.shape[1], "point")
    xyz = np.ascontiguousarray(points[:3].transpose(2, 1, 0))  # (T, n, 3)
    residuals = np.asarray(c3d["data"]["meta_points"]["residuals"], dtype=np.float64)
    if residuals.shape == (1, points.shape[1], points.shape[2]):
        xyz[residuals[0].T < 0] = np.nan  # invalid points (ezc3d already returns NaN for them)
    t0 = first / rate
    time = finish_time(t0 + np.arange(xyz.shape[0]) / rate, spec, t0)
    unit = _first_string(point, "UNITS")
    tables = {"points": Table(
        name="points", time=time, columns={lab: xyz[:, k] for k, lab in enumerate(labels)}, kind=POINTS,
        units={lab: unit for lab in labels} if unit else {}, rate_hz=rate,
        notes=() if unit else (f"{path.name}: no POINT:UNITS; state the markers' unit in the map",))}
    analogs = np.asarray(c3d["data"]["analogs"], dtype=np.float64)  # (1, m, T_a)
    if analogs.ndim == 3 and analogs.shape[1] > 0 and analogs.shape[2] > 0:
        analog = params.get("ANALOG", {})
        arate = _number(analog, "RATE")
        if not arate:
            raise LogFormatError(f"{path}: C3D has analog data but no ANALOG:RATE")
        alabels = _labels(analog, "LABELS", analogs.shape[1], "analog")
        aunits = _strings(analog, "UNITS")
        atime = finish_time(t0 + np.arange(analogs.shape[2]) / arate, spec, t0)
        tables["analogs"] = Table(
            name="analogs", time=atime, columns={lab: analogs[0, k] for k, lab in enumerate(alabels)},
            kind=GENERIC, units={lab: u for lab, u in zip(alabels, aunits, strict=False) if u}, rate_hz=arate)
    return tables


def _check_complete(path: Path, spec: SourceSpec, frames: int, rate: float) -> None:
    """Refuse (or, with ``allow_truncated``, warn about) fewer frames than the header announces."""
    announced = header_frames(path)
    if announced is None or frames >= announced:
        return
    what = (f"{path.name}: truncated: the header announces {announced} frames ({announced / rate:.4g} s), "
            f"the file holds {frames} ({frames / rate:.4g} s)")
    if not spec.allow_truncated:
        raise LogFormatError(f"{what}; export it again, or set `allow_truncated: true` for this source in the "
                             f"map to import the {frames} frames read")
    log.warning("%s; importing the %d frames read (allow_truncated)", what, frames)


def header_frames(path: Path) -> int | None:
    """Frames the C3D header announces (last - first + 1), or None when it cannot say (the 16-bit
    last frame overflows past 65535 frames; the parameter section then holds the count)."""
    with open(path, "rb") as fh:
        head = fh.read(512)
        if len(head) < 12:
            return None
        fh.seek(max(head[0] - 1, 0) * 512 + 3)
        processor = fh.read(1)
    order = ">" if processor == bytes([86]) else "<"  # 84 Intel, 85 DEC: little-endian; 86 MIPS: big
    first, last = struct.unpack(order + "HH", head[6:10])
    if last == 0xFFFF or last < first:
        return None
    return last - first + 1


def _labels(group: dict, key: str, n: int, prefix: str) -> list[str]:
    """LABELS, LABELS2, ... joined; blank labels named ``<prefix><k>``; duplicates are an error."""
    labels = _strings(group, key)
    k = 2
    while len(labels) < n and f"{key}{k}" in group:
        labels += _strings(group, f"{key}{k}")
        k += 1
    labels = [lab or f"{prefix}{i + 1}" for i, lab in enumerate(labels[:n])]
    labels += [f"{prefix}{i + 1}" for i in range(len(labels), n)]
    seen = set()
    for lab in labels:
        if lab in seen:
            raise LogFormatError(f"C3D {prefix} label {lab!r} appears twice")
        seen.add(lab)
    return labels


def _strings(group: dict, key: str) -> list[str]:
    value = group.get(key, {}).get("value", [])
    return [str(v).strip() for v in value]


def _first_string(group: dict, key: str) -> str | None:
    values = _strings(group, key)
    return values[0] if values and values[0] else None


def _number(group: dict, key: str) -> float | None:
    value = group.get(key, {}).get("value")
    if value is None or len(value) == 0:
        return None
    return float(np.asarray(value).ravel()[0])
