"""Writers of small lab files for the import tests: C3D (ezc3d), ROS bags (rosbags), rostopic CSVs."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def write_c3d(path, labels, xyz, rate, unit="mm", first_frame=0, analogs=None) -> Path:
    """A C3D file: markers ``xyz`` (T, K, 3) in ``unit`` (NaN: not seen, written with residual -1);
    ``analogs``: (labels, data (T * r, m), units) at ``r`` × ``rate``."""
    import ezc3d

    c3d = ezc3d.c3d()
    c3d["parameters"]["POINT"]["RATE"]["value"] = [float(rate)]
    c3d["parameters"]["POINT"]["LABELS"]["value"] = tuple(labels)
    c3d["parameters"]["POINT"]["UNITS"]["value"] = [unit] if unit else []
    T, K = xyz.shape[:2]
    points = np.ones((4, K, T))
    seen = ~np.isnan(xyz).any(axis=2)  # (T, K)
    points[:3] = np.where(seen[..., None], xyz, 0.0).transpose(2, 1, 0)
    c3d["data"]["points"] = points
    residuals = np.where(seen.T, 0.5, -1.0)[None]
    c3d["data"]["meta_points"]["residuals"] = residuals
    c3d["data"]["meta_points"]["camera_masks"] = np.zeros((7, K, T), dtype=bool)
    if analogs is not None:
        alabels, adata, aunits = analogs
        ratio = adata.shape[0] // T
        c3d["parameters"]["ANALOG"]["RATE"]["value"] = [float(rate * ratio)]
        c3d["parameters"]["ANALOG"]["LABELS"]["value"] = tuple(alabels)
        c3d["parameters"]["ANALOG"]["UNITS"]["value"] = list(aunits)
        c3d["data"]["analogs"] = adata.T[None]
    c3d["header"]["points"]["first_frame"] = int(first_frame)
    c3d.write(str(path))
    return Path(path)


EPOCH_NS = 1_700_000_000_000_000_000  # ROS time of the test recordings' t = 0, ns


def write_bag(path, kind, names, time, position, velocity=None, effort=None, extra=None, stamp_offset=0.0,
              publishers=()) -> Path:
    """A bag with a ``/joint_states`` topic (``sensor_msgs/JointState``) and optional
    ``/wrench`` (``geometry_msgs/WrenchStamped``, extra: (T, 6) force xyz, torque xyz).

    kind: ros1 (``path`` a .bag file), db3 or mcap (``path`` a ROS 2 bag folder). Header stamps
    are EPOCH_NS + ``time`` (s); the bag's receive time is ``stamp_offset`` s later.
    ``publishers``: more drivers on ``/joint_states``, each (names, time, position, effort or None).
    """
    from rosbags.typesys import Stores, get_typestore

    path = Path(path)
    store = get_typestore(Stores.ROS1_NOETIC if kind == "ros1" else Stores.ROS2_HUMBLE)
    T = store.types
    js_type, w_type = "sensor_msgs/msg/JointState", "geometry_msgs/msg/WrenchStamped"

    def header(t):
        ns = EPOCH_NS + int(round(t * 1e9))
        stamp = T["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
        if kind == "ros1":
            return T["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id="")
        return T["std_msgs/msg/Header"](stamp=stamp, frame_id="")

    def empty():
        return np.zeros(0)

    def joint_states(names, time, position, velocity, effort):
        for i, t in enumerate(time):
            js = T[js_type](header=header(t), name=list(names), position=np.asarray(position[i], float),
                            velocity=empty() if velocity is None else np.asarray(velocity[i], float),
                            effort=empty() if effort is None else np.asarray(effort[i], float))
            yield "js", EPOCH_NS + int(round((t + stamp_offset) * 1e9)), js

    def messages():
        yield from joint_states(names, time, position, velocity, effort)
        for more_names, more_time, more_position, more_effort in publishers:
            yield from joint_states(more_names, more_time, more_position, None, more_effort)
        for i, t in enumerate(time):
            if extra is not None:
                v = T["geometry_msgs/msg/Vector3"]
                w = T[w_type](header=header(t), wrench=T["geometry_msgs/msg/Wrench"](
                    force=v(x=extra[i, 0], y=extra[i, 1], z=extra[i, 2]),
                    torque=v(x=extra[i, 3], y=extra[i, 4], z=extra[i, 5])))
                yield "w", EPOCH_NS + int(round((t + stamp_offset) * 1e9)), w

    if kind == "ros1":
        from rosbags.rosbag1 import Writer

        serialize = store.serialize_ros1
        writer = Writer(path)
    else:
        from rosbags.rosbag2 import StoragePlugin, Writer

        serialize = store.serialize_cdr
        plugin = StoragePlugin.SQLITE3 if kind == "db3" else StoragePlugin.MCAP
        writer = Writer(path, version=9, storage_plugin=plugin)
    with writer:
        conns = {"js": writer.add_connection("/joint_states", js_type, typestore=store)}
        if extra is not None:
            conns["w"] = writer.add_connection("/wrench", w_type, typestore=store)
        for key, ns, msg in sorted(messages(), key=lambda m: m[1]):  # in time order, as recorded
            writer.write(conns[key], ns, serialize(msg, js_type if key == "js" else w_type))
    return path


def write_rostopic_csv(path, names, time, position, velocity, effort, receive_offset=0.0) -> Path:
    """``rostopic echo -p /joint_states`` output: %time and header stamps in ns (EPOCH_NS + ``time``
    s; received ``receive_offset`` s later), field.* columns."""
    n = len(names)
    head = ["%time", "field.header.seq", "field.header.stamp", "field.header.frame_id"]
    head += [f"field.name{k}" for k in range(n)]
    for q in ("position", "velocity", "effort"):
        head += [f"field.{q}{k}" for k in range(n)]
    lines = [",".join(head)]
    for i, t in enumerate(time):
        row = [str(EPOCH_NS + int(round((t + receive_offset) * 1e9))), str(i), str(EPOCH_NS + int(round(t * 1e9))), ""]
        row += list(names)
        for arr in (position, velocity, effort):
            row += [repr(float(v)) for v in arr[i]]
        lines.append(",".join(row))
    Path(path).write_text("\n".join(lines) + "\n")
    return Path(path)
