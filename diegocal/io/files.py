"""Reading and writing logs (HDF5, CSV) and YAML parameter files; the only code that opens files.

Every write is atomic: content goes to a temporary file beside the target, which is renamed
over it only once complete, so a crash never leaves a half-written output (DESIGN.md).
"""

from __future__ import annotations

import contextlib
import csv
import logging
import math
import os
import re
import shlex
import tempfile
from pathlib import Path

import h5py
import numpy as np
import yaml

from diegocal.errors import DamagedFileError, DiegocalError, InputFileError, LogFormatError
from diegocal.io.log import FORMAT, VECTOR_STREAMS, VERSION, Log, Stream, Truth, unknown_streams

LOG = logging.getLogger(__name__)

HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
CSV_HEADER_PREFIX = "# diegocal-log"
AXES = ("x", "y", "z")
#: libyaml's parser where PyYAML was built with it (the same mappings, several times faster on a
#: robot's sensors.yaml or a log's truth), else PyYAML's own.
YAML_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


# ----------------------------------------------------------------------------- atomic writes
@contextlib.contextmanager
def atomic_path(path: str | os.PathLike):
    """Yield a temporary path beside ``path``; rename it over ``path`` on success only."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; outputs should look like any other file
    try:
        yield Path(tmp)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def write_text(path, text: str) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


# ----------------------------------------------------------------------------- YAML
def to_plain(obj, nan_as_none: bool = False):
    """numpy scalars/arrays -> plain Python, recursively, so YAML stays readable; with
    ``nan_as_none`` a NaN becomes None (YAML's null: "not known"; an infinite bound stays .inf)."""
    if isinstance(obj, dict):
        return {str(k): to_plain(v, nan_as_none) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_plain(v, nan_as_none) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_plain(obj.tolist(), nan_as_none)
    if isinstance(obj, np.generic):
        obj = obj.item()
    if nan_as_none and isinstance(obj, float) and math.isnan(obj):
        return None
    return obj


def dump_yaml(data) -> str:
    return yaml.safe_dump(to_plain(data), sort_keys=False, default_flow_style=None, width=100, allow_unicode=True)


def save_yaml(data, path) -> None:
    write_text(path, dump_yaml(data))


def parse_yaml(text: str):
    """YAML text -> Python objects, as ``yaml.safe_load`` reads it (:data:`YAML_LOADER`)."""
    return yaml.load(text, Loader=YAML_LOADER)


def load_yaml(path) -> dict:
    path = _existing(path)
    try:
        data = parse_yaml(path.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" (line {mark.line + 1})" if mark is not None else ""
        raise InputFileError(f"{path}: not valid YAML{where}") from None
    except UnicodeDecodeError:  # a log or another binary file where a YAML one was meant
        raise InputFileError(f"{path}: not a YAML file (binary: a log in the place of a model?)") from None
    if not isinstance(data, dict):
        raise InputFileError(f"{path}: expected a YAML mapping at the top level")
    return data


# ----------------------------------------------------------------------------- logs
def load_log(path, nan_ok: bool = False) -> Log:
    """Read a log from ``.h5`` or ``.csv``; one clear :class:`LogFormatError` when invalid.
    ``nan_ok`` accepts NaN in every stream (for describing a log, not for fitting it)."""
    path = _existing(path)
    with open(path, "rb") as fh:
        head = fh.read(8)
    if head == HDF5_SIGNATURE:
        return _load_h5(path, nan_ok)
    if path.suffix.lower() == ".csv":
        return _load_csv(path, nan_ok)
    raise LogFormatError(f"{path}: not a diegocal log (expected an HDF5 .h5 or a .csv file)")


def log_robot(path) -> str | None:
    """The robot a log names, read from its header only (no stream is loaded)."""
    path = _existing(path)
    with open(path, "rb") as fh:
        head = fh.read(8)
    if head == HDF5_SIGNATURE:
        try:
            with h5py.File(path, "r") as f:
                return _attr_str(f.attrs.get("robot")) or None
        except OSError as exc:  # a truncated copy: as load_log says it
            raise LogFormatError(f"{path}: cannot read HDF5 file ({exc})") from None
    with open(path, errors="replace") as fh:
        first = fh.readline().strip()
    return header_fields(first).get("robot") if first.startswith(CSV_HEADER_PREFIX) else None


def log_streams(path) -> tuple[str, ...]:
    """The stream names of a log, read from its header only (HDF5 groups, CSV column prefixes).

    Raises LogFormatError when the file is not a diegocal log (another HDF5 file, another CSV)."""
    path = _existing(path)
    with open(path, "rb") as fh:
        head = fh.read(8)
    if head == HDF5_SIGNATURE:
        f = _open_h5(path)
        try:
            with f:
                fmt = _attr_str(f.attrs.get("format"))
                names = tuple(k for k in f if k not in ("time", "truth"))
        except DAMAGE as exc:
            raise _damaged(path, exc) from None
        if fmt != FORMAT:
            raise LogFormatError(f"{path}: format attribute is {fmt!r}, expected {FORMAT!r}")
        return names
    if path.suffix.lower() != ".csv":
        raise LogFormatError(f"{path}: not a diegocal log (expected an HDF5 .h5 or a .csv file)")
    first = _nth_line(path, 0)
    columns = _nth_line(path, 1) if first.startswith("#") else first
    if (first.startswith("#") and not first.startswith(CSV_HEADER_PREFIX)) or not columns.startswith("time"):
        raise LogFormatError(f"{path}: not a diegocal CSV log (no '{CSV_HEADER_PREFIX}' header or 'time' column)")
    return tuple(dict.fromkeys(c.split(".", 1)[0] for c in columns.split(",")[1:] if "." in c))


def save_log(log: Log, path) -> None:
    """Write a log; the format follows the suffix (``.h5``/``.hdf5`` or ``.csv``)."""
    save_logs([(log, path)])


def save_logs(pairs) -> None:
    """Write several logs ``[(log, path), ...]`` together: each goes to a temporary file, and they
    are renamed over their targets only once every one is complete (a failure leaves none)."""
    pairs = [(log, Path(path)) for log, path in pairs]
    writers = []
    for _, path in pairs:
        suffix = path.suffix.lower()
        if suffix in (".h5", ".hdf5"):
            writers.append(_save_h5)
        elif suffix == ".csv":
            writers.append(_save_csv)
        else:
            raise LogFormatError(f"{path}: unknown log suffix {suffix!r} (use .h5 or .csv)")
    with contextlib.ExitStack() as stack:
        tmps = [stack.enter_context(atomic_path(path)) for _, path in pairs]
        for (log, _), tmp, write in zip(pairs, tmps, writers, strict=True):
            write(log, tmp)


def q_log_path(calib_path) -> Path:
    """The tracked joint angles a calibration writes beside itself: ``<stem>.q.h5``
    (``x.calib.yaml`` -> ``x.q.h5``)."""
    calib_path = Path(calib_path)
    name = calib_path.name
    for suffix in (".calib.yaml", ".yaml", ".yml"):
        if name.endswith(suffix):
            return calib_path.with_name(name[: -len(suffix)] + ".q.h5")
    return calib_path.with_name(name + ".q.h5")


def _existing(path) -> Path:
    path = Path(path)
    if not path.exists():
        raise InputFileError(f"{path}: no such file")
    if path.is_dir():
        raise InputFileError(f"{path}: is a directory, expected a file")
    return path


def _save_h5(log: Log, path: Path) -> None:
    with h5py.File(path, "w") as f:
        f.attrs["format"] = FORMAT
        f.attrs["version"] = VERSION
        if log.robot is not None:
            f.attrs["robot"] = log.robot
        if log.rate_hz is not None:
            f.attrs["rate_hz"] = float(log.rate_hz)
        if log.source:
            f.attrs["source"] = dump_yaml(log.source)
        f.create_dataset("time", data=log.time)
        for name, stream in log.streams.items():
            _write_stream(f.create_group(name), stream)
        if log.truth is not None:
            g = f.create_group("truth")
            g.attrs["params"] = dump_yaml(log.truth.params)
            g.attrs["effects"] = dump_yaml(log.truth.effects)
            for name, stream in log.truth.signals.items():
                _write_stream(g.create_group(name), stream)


def _write_stream(group, stream: Stream) -> None:
    group.create_dataset("names", data=np.array(stream.names, dtype=h5py.string_dtype()))
    group.create_dataset("data", data=stream.data, compression="gzip", compression_opts=4, shuffle=True)


def _read_stream(group, where: str) -> Stream:
    if "names" not in group or "data" not in group:
        raise LogFormatError(f"{where}: a stream group needs 'names' and 'data' datasets")
    names = tuple(n.decode() if isinstance(n, bytes) else str(n) for n in group["names"][()])
    data = np.asarray(group["data"][()])
    if not np.issubdtype(data.dtype, np.number):
        raise LogFormatError(f"{where}/data: expected numbers, got {data.dtype}")
    return Stream(names, data.astype(np.float64, copy=False))


#: What h5py raises where a damaged file's bytes are read (its object headers, B-trees, chunks).
DAMAGE = (OSError, RuntimeError, KeyError, ValueError, TypeError)


def _open_h5(path: Path):
    try:
        return h5py.File(path, "r")
    except OSError as exc:
        raise LogFormatError(f"{path}: cannot read HDF5 file ({exc})") from None


def _damaged(path: Path, exc: BaseException) -> DamagedFileError:
    return DamagedFileError(f"{path}: damaged HDF5 file, it cannot be read ({exc})")


def _load_h5(path: Path, nan_ok: bool = False) -> Log:
    f = _open_h5(path)
    try:
        return _read_h5(f, path, nan_ok)
    except DiegocalError:  # the log's own faults (a LogFormatError is a ValueError too)
        raise
    except DAMAGE as exc:  # a damaged file opens, then fails where its bytes are read
        raise _damaged(path, exc) from None


def _read_h5(f, path: Path, nan_ok: bool) -> Log:
    with f:
        fmt = _attr_str(f.attrs.get("format"))
        if fmt != FORMAT:
            raise LogFormatError(f"{path}: format attribute is {fmt!r}, expected {FORMAT!r}")
        version = f.attrs.get("version")
        if version is None or int(version) != VERSION:
            raise LogFormatError(f"{path}: log format version {version}, this diegocal reads version {VERSION}")
        if "time" not in f:
            raise LogFormatError(f"{path}: no /time dataset")
        time = np.asarray(f["time"][()], dtype=np.float64)
        streams = {}
        truth = None
        for key in f:
            if key == "time":
                continue
            if key == "truth":
                g = f["truth"]
                signals = {k: _read_stream(g[k], f"{path}:/truth/{k}") for k in g}
                truth = Truth(
                    params=parse_yaml(_attr_str(g.attrs.get("params")) or "{}") or {},
                    effects=parse_yaml(_attr_str(g.attrs.get("effects")) or "[]") or [],
                    signals=signals,
                )
                continue
            if not isinstance(f[key], h5py.Group):
                raise LogFormatError(f"{path}: /{key} should be a stream group (names, data)")
            streams[key] = _read_stream(f[key], f"{path}:/{key}")
        _say_unknown(unknown_streams(streams, str(path)), path)
        robot = _attr_str(f.attrs.get("robot"))
        rate = f.attrs.get("rate_hz")
        try:
            source = parse_yaml(_attr_str(f.attrs.get("source")) or "null")
        except yaml.YAMLError:
            raise LogFormatError(f"{path}: the 'source' attribute is not YAML") from None
    try:
        return Log(
            time=time,
            streams=streams,
            robot=robot or None,
            rate_hz=float(rate) if rate is not None else None,
            truth=truth,
            nan_ok=nan_ok,
            source=source if isinstance(source, dict) else None,
        )
    except LogFormatError as exc:
        raise LogFormatError(f"{path}: {exc}") from None


def _attr_str(value) -> str | None:
    if value is None:
        return None
    if isinstance(value, bytes):
        return value.decode()
    return str(value)


# ----------------------------------------------------------------------------- CSV
def header_fields(first: str) -> dict:
    """The ``key=value`` attributes of a CSV log's first line (:data:`CSV_HEADER_PREFIX` ...); a
    value with a space is quoted (:func:`_csv_header`: ``robot='/my robot'``); a value that does
    not start with a quote is read as it is (a Windows path's backslashes, an apostrophe)."""
    text = first[len(CSV_HEADER_PREFIX) :]
    try:
        words = shlex.split(text) if re.search(r"=['\"]", text) else text.split()
    except ValueError:  # an unmatched quote: the words as they stand
        words = text.split()
    return dict(w.split("=", 1) for w in words if "=" in w)


def _csv_header(log: Log) -> str:
    fields = [f"version={VERSION}"]
    if log.robot:
        robot = str(log.robot)
        plain = not any(c.isspace() or c in "'\"" for c in robot)
        fields.append(f"robot={robot if plain else shlex.quote(robot)}")
    if log.rate_hz is not None:
        fields.append(f"rate_hz={log.rate_hz!r}")
    return f"{CSV_HEADER_PREFIX} " + " ".join(fields)


def _save_csv(log: Log, path: Path) -> None:
    columns = ["time"]
    blocks = [log.time[:, None]]
    for name, stream in log.streams.items():
        if name in VECTOR_STREAMS:
            columns += [f"{name}.{n}.{a}" for n in stream.names for a in AXES]
            blocks.append(stream.data.reshape(log.n_samples, -1))
        else:
            columns += [f"{name}.{n}" for n in stream.names]
            blocks.append(stream.data)
    table = np.hstack(blocks)
    with open(path, "w") as fh:
        fh.write(_csv_header(log) + "\n")
        fh.write(",".join(columns) + "\n")
        np.savetxt(fh, table, delimiter=",", fmt="%.17g")


def _load_csv(path: Path, nan_ok: bool = False) -> Log:
    import pandas as pd  # lazy: half a second, for CSV logs only

    robot, rate = None, None
    with open(path, errors="replace") as fh:
        first = fh.readline().strip()
    skip = 0
    if first.startswith("#"):
        skip = 1
        if not first.startswith(CSV_HEADER_PREFIX):
            raise LogFormatError(f"{path}: header comment is not '{CSV_HEADER_PREFIX} ...'")
        meta = header_fields(first)
        if meta.get("version", str(VERSION)) != str(VERSION):
            raise LogFormatError(f"{path}: log format version {meta['version']}, this diegocal reads version {VERSION}")
        robot = meta.get("robot")
        rate = float(meta["rate_hz"]) if "rate_hz" in meta else None
    try:
        frame = pd.read_csv(path, skiprows=skip)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise LogFormatError(f"{path}: cannot parse CSV ({str(exc).splitlines()[0]})") from None
    if "time" not in frame.columns:
        raise LogFormatError(f"{path}: CSV has no 'time' column")
    header = next(csv.reader([_nth_line(path, skip)]))
    seen = set()
    for col in header:
        if col in seen:
            raise LogFormatError(f"{path}: duplicate column {col!r}")
        seen.add(col)
    frame.columns = header
    last = next(csv.reader([_last_line(path)]), [])
    if len(frame) and 0 < len(last) < len(header):  # a row cut off: the file ends mid-row
        raise LogFormatError(f"{path}: its last row has {len(last)} of {len(header)} fields: the file looks cut short")
    try:
        table = frame.apply(pd.to_numeric, errors="raise").to_numpy(dtype=np.float64)
    except (ValueError, TypeError):
        raise LogFormatError(f"{path}: CSV holds non-numeric values") from None
    columns = list(frame.columns)
    time = table[:, 0]
    order: dict[str, list[str]] = {}
    index: dict[str, list[int]] = {}
    for i, col in enumerate(columns[1:], start=1):
        if "." not in col:
            raise LogFormatError(f"{path}: column {col!r} is not '<stream>.<name>'")
        stream, rest = col.split(".", 1)
        if stream in VECTOR_STREAMS:
            if rest[-2:] not in (".x", ".y", ".z"):
                raise LogFormatError(f"{path}: column {col!r} should end in .x, .y or .z")
            rest = rest[:-2]
        order.setdefault(stream, [])
        if not order[stream] or order[stream][-1] != rest or stream not in VECTOR_STREAMS:
            order[stream].append(rest)
        index.setdefault(stream, []).append(i)
    _say_unknown(unknown_streams(order, str(path)), path)
    streams = {}
    for stream, names in order.items():
        cols = table[:, index[stream]]
        if stream in VECTOR_STREAMS:
            if cols.shape[1] != 3 * len(names):
                raise LogFormatError(f"{path}: stream '{stream}' needs x, y, z columns for every name")
            cols = cols.reshape(len(time), len(names), 3)
        streams[stream] = Stream(tuple(names), np.ascontiguousarray(cols))
    try:
        return Log(time=np.ascontiguousarray(time), streams=streams, robot=robot, rate_hz=rate, nan_ok=nan_ok)
    except LogFormatError as exc:
        raise LogFormatError(f"{path}: {exc}") from None


def _say_unknown(names: list, path: Path) -> None:
    if names:
        LOG.warning(
            f"{path}: kept stream(s) {', '.join(repr(n) for n in names)} that no diegocal command reads "
            "(not one of DESIGN.md's streams)"
        )


def _nth_line(path: Path, n: int) -> str:
    with open(path, errors="replace") as fh:
        for i, line in enumerate(fh):
            if i == n:
                return line.rstrip("\n")
    return ""


def _last_line(path: Path) -> str:
    """The file's last non-empty line (read from its end: a log may be long)."""
    with open(path, "rb") as fh:
        fh.seek(0, 2)
        fh.seek(max(fh.tell() - 65536, 0))
        lines = [line for line in fh.read().decode(errors="replace").splitlines() if line.strip()]
    return lines[-1] if lines else ""

