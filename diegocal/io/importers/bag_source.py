"""ROS bags through rosbags (no ROS install): ROS 1 ``.bag``, ROS 2 ``.db3`` / ``.mcap`` or a bag folder.

One table per topic, read only when a stream asks for it. ``sensor_msgs/JointState`` gives columns
``position.<joint>``, ``velocity.<joint>``, ``effort.<joint>`` (an empty array, as drivers send
for what they do not measure, gives no column). Any other message is flattened to its numeric
fields: ``data``, ``wrench.force.x``, ``data.0`` for the first element of an array. Time: the
message's ``header.stamp`` where it has a non-zero one (``stamp: receive`` in the map: always the
time the bag recorded it), in s. ROS 2 bags without embedded message definitions are read with
the Humble type store.
"""

from __future__ import annotations

import contextlib
from pathlib import Path

import numpy as np

from diegocal.errors import LogFormatError
from diegocal.io.importers.mapping import SourceSpec
from diegocal.io.importers.tables import GENERIC, JOINT_STATE, Source, Table, check_increasing, finish_time, sort_unique

JOINT_STATE_TYPES = ("sensor_msgs/msg/JointState", "sensor_msgs/JointState")


def open_bag(path: Path, spec: SourceSpec) -> Source:
    """A bag source: its topics are the tables; the only JointState topic is the default one."""
    with _reader(path) as reader:
        topics = {c.topic: c.msgtype for c in reader.connections}
        start = reader.start_time if topics else 0
    if not topics:
        raise LogFormatError(f"{path}: the bag holds no topics")
    joint_states = [t for t, typ in topics.items() if typ in JOINT_STATE_TYPES]
    return Source(spec=spec, path=path, kind="bag", table_names=tuple(topics),
                  loader=lambda topic: _read_topic(path, spec, topic, topics[topic], start),
                  default_table=joint_states[0] if len(joint_states) == 1 else None)


@contextlib.contextmanager
def _reader(path: Path):
    """An open rosbags ``AnyReader``; its errors become one :class:`LogFormatError` line."""
    try:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore
    except ImportError:  # pragma: no cover - a runtime dependency
        raise LogFormatError("reading ROS bags needs the rosbags package (pip install rosbags)") from None
    try:
        reader = AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
        reader.open()
    except Exception as exc:  # noqa: BLE001 - rosbags raises its own error family and OSError/sqlite errors
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise LogFormatError(f"{path}: not a readable ROS bag ({first})") from None
    try:
        yield reader
    finally:
        reader.close()


def _read_topic(path: Path, spec: SourceSpec, topic: str, msgtype: str, start: int) -> Table:
    """One topic's messages; ``start``: the bag's first receive time, ns (the origin of zero_time)."""
    where = f"{path.name} {topic}"
    stamps, rows = [], []
    joint_state = msgtype in JOINT_STATE_TYPES
    names_seen = None
    with _reader(path) as reader:
        connections = [c for c in reader.connections if c.topic == topic]
        try:
            for connection, received, raw in reader.messages(connections=connections):
                msg = reader.deserialize(raw, connection.msgtype)
                stamps.append(_stamp(msg, received, spec.stamp))
                if joint_state:
                    names = tuple(str(n) for n in msg.name)
                    if names_seen is None:
                        names_seen = names
                    elif set(names) != set(names_seen):
                        raise LogFormatError(
                            f"{where}: messages name different joints ({', '.join(names_seen[:4])}... then "
                            f"{', '.join(names[:4])}...); split the topic before importing")
                    rows.append(_joint_state_row(msg, names, where))
                else:
                    rows.append(dict(_flatten(msg, "")))
        except LogFormatError:
            raise
        except Exception as exc:  # noqa: BLE001 - a corrupt message
            raise LogFormatError(f"{where}: cannot read a message ({str(exc).splitlines()[0]})") from None
    if not rows:
        raise LogFormatError(f"{where}: no messages")
    keys = list(dict.fromkeys(k for row in rows for k in row))
    values = [np.array([row.get(k, np.nan) for row in rows], dtype=np.float64) for k in keys]
    ns = np.asarray(stamps, dtype=np.int64)
    rel = (ns - start) * 1e-9  # exact to the ns before the conversion to float seconds
    time, values, notes = sort_unique(ns * 1e-9, values + [rel], where)
    rel = values.pop()
    check_increasing(time, where)
    time = finish_time(time, spec, start * 1e-9, rel)
    return Table(name=topic, time=time, columns=dict(zip(keys, values, strict=True)),
                 kind=JOINT_STATE if joint_state else GENERIC, notes=notes)


def _stamp(msg, received_ns: int, mode: str) -> int:
    """The message's time, ns: its header stamp (when non-zero and asked for) or the receive time."""
    header = getattr(msg, "header", None)
    if mode == "header" and header is not None:
        stamp = header.stamp
        ns = int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)
        if ns > 0:
            return ns
    return int(received_ns)


def _joint_state_row(msg, names, where: str) -> dict:
    row = {}
    for quantity in ("position", "velocity", "effort"):
        values = np.asarray(getattr(msg, quantity), dtype=np.float64)
        if values.size == 0:
            continue
        if values.size != len(names):
            raise LogFormatError(f"{where}: {values.size} {quantity} values for {len(names)} joint names")
        row.update({f"{quantity}.{n}": v for n, v in zip(names, values, strict=True)})
    return row


def _flatten(value, prefix: str):
    """(column, number) pairs of a message's numeric fields; strings and headers left out."""
    if isinstance(value, bool | int | float | np.number):
        yield prefix, float(value)
    elif isinstance(value, np.ndarray):
        if np.issubdtype(value.dtype, np.number):
            for i, v in enumerate(value.ravel()):
                yield f"{prefix}.{i}" if prefix else str(i), float(v)
    elif isinstance(value, list | tuple):
        for i, v in enumerate(value):
            yield from _flatten(v, f"{prefix}.{i}" if prefix else str(i))
    elif hasattr(value, "__dataclass_fields__"):
        for name in value.__dataclass_fields__:
            if name in ("header", "__msgtype__"):
                continue
            yield from _flatten(getattr(value, name), f"{prefix}.{name}" if prefix else name)
