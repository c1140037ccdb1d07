"""ROS bags through rosbags (no ROS install): ROS 1 ``.bag``, ROS 2 ``.db3`` / ``.mcap`` or a bag folder.

One table per topic, read only when a stream asks for it. ``sensor_msgs/JointState`` gives columns
``position.<joint>``, ``velocity.<joint>``, ``effort.<joint>`` (an empty array, as drivers send
for what they do not measure, gives no column). Any other message is flattened to its numeric
fields: ``data``, ``wrench.force.x``, ``data.0`` for the first element of an array. Time: the
message's ``header.stamp`` where it has a non-zero one (``stamp: receive`` in the map: always the
time the bag recorded it), in s. ``zero_time`` subtracts the earliest of those same stamps over
every topic of the bag, so the log starts at 0 (a header stamp is earlier than its receive time:
zeroing on the first receive time started logs at -2.3 ms). ROS 2 bags without embedded message
definitions are read with the Humble type store.
"""

from __future__ import annotations

import contextlib
from pathlib import Path

import numpy as np

from diegocal.errors import LogFormatError
from diegocal.io.importers.mapping import SourceSpec
from diegocal.io.importers.signals import default_max_gap, resample
from diegocal.io.importers.tables import GENERIC, JOINT_STATE, Source, Table, check_increasing, finish_time, sort_unique

JOINT_STATE_TYPES = ("sensor_msgs/msg/JointState", "sensor_msgs/JointState")


def open_bag(path: Path, spec: SourceSpec) -> Source:
    """A bag source: its topics are the tables; the only JointState topic is the default one."""
    with _reader(path) as reader:
        topics = {c.topic: c.msgtype for c in reader.connections}
        start = _first_stamp(reader, spec.stamp, path) if topics and spec.zero_time else reader.start_time
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
        raise LogFormatError(f"{path}: not a readable ROS bag ({first}){_reindex_hint(path, first)}") from None
    try:
        yield reader
    finally:
        reader.close()


def _first_stamp(reader, mode: str, where: Path) -> int:
    """The earliest time stamp (ns) of the bag in ``mode`` (header or receive): the first message
    of each topic, read until every topic has given one."""
    first: dict[int, int] = {}
    want = {c.id for c in reader.connections}
    try:
        for connection, received, raw in reader.messages():
            if connection.id not in first:
                first[connection.id] = _stamp(reader.deserialize(raw, connection.msgtype), received, mode)
                if len(first) == len(want):
                    break
    except Exception as exc:  # noqa: BLE001 - a corrupt message
        raise LogFormatError(f"{where}: cannot read a message ({str(exc).splitlines()[0]})") from None
    return min(first.values()) if first else int(reader.start_time)


def _reindex_hint(path: Path, error: str) -> str:
    """A ROS 1 bag whose index is missing or cut off (recording killed, copy stopped) can be rebuilt
    from its chunks by ``rosbag reindex`` (rosbags, which reads it here, has no reindex)."""
    if path.is_dir() or "index" not in error.lower():
        return ""
    return (f"; it looks truncated or never closed: rebuild its index with `rosbag reindex {path.name}` "
            "(ROS 1) and import the reindexed bag")


def _read_topic(path: Path, spec: SourceSpec, topic: str, msgtype: str, start: int) -> Table:
    """One topic's messages; ``start``: the bag's first time stamp, ns (the origin of zero_time).

    Several publishers on one JointState topic (an arm and a gripper driver, each naming its own
    joints) are merged by joint name onto the stamps of the one that publishes most, inside the
    span every publisher covers; the others' values are read there linearly (no gap of more than
    ten of their periods bridged). Two publishers naming the same joint are an error.
    """
    where = f"{path.name} {topic}"
    groups: dict[frozenset, tuple[list, list]] = {}
    joint_state = msgtype in JOINT_STATE_TYPES
    with _reader(path) as reader:
        connections = [c for c in reader.connections if c.topic == topic]
        try:
            for connection, received, raw in reader.messages(connections=connections):
                msg = reader.deserialize(raw, connection.msgtype)
                names = tuple(str(n) for n in msg.name) if joint_state else ()
                stamps, rows = groups.setdefault(frozenset(names), ([], []))
                stamps.append(_stamp(msg, received, spec.stamp))
                rows.append(_joint_state_row(msg, names, where) if joint_state else dict(_flatten(msg, "")))
        except LogFormatError:
            raise
        except Exception as exc:  # noqa: BLE001 - a corrupt message
            raise LogFormatError(f"{where}: cannot read a message ({str(exc).splitlines()[0]})") from None
    if not groups:
        raise LogFormatError(f"{where}: no messages")
    parts = sorted((_group(stamps, rows, start, where) for stamps, rows in groups.values()),
                   key=lambda g: -g[0].shape[0])
    ns, rel, columns, notes = parts[0]
    if len(parts) > 1:
        ns, rel, columns, notes = _merge(parts, groups, where)
    time = finish_time(ns * 1e-9, spec, start * 1e-9, rel)
    return Table(name=topic, time=time, columns=columns, kind=JOINT_STATE if joint_state else GENERIC, notes=notes)


def _group(stamps: list, rows: list, start: int, where: str):
    """(stamps ns, stamps relative to ``start`` s, columns, notes) of one publisher's messages, sorted."""
    keys = list(dict.fromkeys(k for row in rows for k in row))
    values = [np.array([row.get(k, np.nan) for row in rows], dtype=np.float64) for k in keys]
    ns = np.asarray(stamps, dtype=np.int64)
    rel = (ns - start) * 1e-9  # exact to the ns before the conversion to float seconds
    rel, values, notes = sort_unique(rel, values + [ns], where)
    ns = values.pop()
    check_increasing(rel, where)
    return ns, rel, dict(zip(keys, values, strict=True)), notes


def _merge(parts: list, groups: dict, where: str):
    """Publishers' columns on the densest one's stamps, within the span they all cover."""
    sets = list(groups)
    for i, a in enumerate(sets):
        for b in sets[i + 1:]:
            if a & b:
                raise LogFormatError(f"{where}: two publishers name joint {sorted(a & b)[0]!r} "
                                     f"({', '.join(sorted(a))} and {', '.join(sorted(b))}); import one of them")
    lo = max(p[1][0] for p in parts)
    hi = min(p[1][-1] for p in parts)
    ns, rel, columns, notes = parts[0]
    keep = (rel >= lo) & (rel <= hi)
    if keep.sum() < 2:
        raise LogFormatError(f"{where}: the publishers on this topic do not overlap in time")
    ns, rel = ns[keep], rel[keep]
    columns = {k: v[keep] for k, v in columns.items()}
    for _, t, cols, more in parts[1:]:
        gap = default_max_gap(t)
        columns.update({k: resample(v, t, rel, "linear", gap) for k, v in cols.items()})
        notes += more
    joints = [", ".join(sorted({c.split(".", 1)[1] for c in p[2]})) for p in parts]
    notes += (f"{where}: {len(parts)} publishers ({'; '.join(joints)}) merged by joint name onto the stamps of "
              f"the first ({_rate(parts[0][1])}), {rel[-1] - rel[0]:.4g} s that all cover",)
    return ns, rel, columns, notes


def _rate(t: np.ndarray) -> str:
    return f"~{1.0 / float(np.median(np.diff(t))):.4g} Hz" if t.shape[0] > 1 else "1 message"


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
