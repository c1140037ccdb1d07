"""Writers of small lab files for the import tests: C3D (ezc3d), ROS bags (rosbags), rostopic CSVs,
TRC, Vicon Nexus and Motive CSVs (by hand); and the numbers of a fitted output, to compare two fits."""

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


def _cell(v) -> str:
    """A number as the vendors write it; NaN (an occluded marker) as an empty cell."""
    return "" if not np.isfinite(v) else f"{float(v):.6f}"


def write_trc(path, labels, xyz, rate, unit="mm", first_frame=1) -> Path:
    """An OpenSim / Cortex TRC file: markers ``xyz`` (T, K, 3) in ``unit``, NaN written as empty cells."""
    T, K = xyz.shape[:2]
    lines = [f"PathFileType\t4\t(X/Y/Z)\t{Path(path).name}",
             "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
             f"{rate:.2f}\t{rate:.2f}\t{T}\t{K}\t{unit}\t{rate:.2f}\t{first_frame}\t{T}",
             "Frame#\tTime\t" + "\t".join(f"{n}\t\t" for n in labels),
             "\t\t" + "\t".join(f"X{k + 1}\tY{k + 1}\tZ{k + 1}" for k in range(K)), ""]
    for i in range(T):
        t = (first_frame - 1 + i) / rate
        lines.append(f"{first_frame + i}\t{t:.5f}\t" + "\t".join(_cell(v) for v in xyz[i].ravel()))
    Path(path).write_text("\n".join(lines) + "\n")
    return Path(path)


def write_vicon_csv(path, labels, xyz, rate, devices=None, unit="mm") -> Path:
    """A Vicon Nexus CSV export: a Devices section (``devices``: (name, channels, data (T * r, m), rate
    r × ``rate``, unit)) then the Trajectories section, markers (T, K, 3) with NaN as empty cells."""
    lines = []
    if devices is not None:
        name, channels, data, dev_unit = devices
        r = data.shape[0] // xyz.shape[0]
        lines += ["Devices", f"{rate * r:g}", ",," + name + "," * len(channels),
                  "Frame,Sub Frame," + ",".join(channels), ",," + ",".join([dev_unit] * len(channels))]
        lines += [f"{i // r + 1},{i % r}," + ",".join(_cell(v) for v in row) for i, row in enumerate(data)]
        lines.append("")
    K = len(labels)
    lines += ["Trajectories", f"{rate:g}", ",," + ",".join(f"{n},," for n in labels),
              "Frame,Sub Frame," + ",".join(["X,Y,Z"] * K), ",," + ",".join([unit] * 3 * K)]
    lines += [f"{i + 1},0," + ",".join(_cell(v) for v in frame.ravel()) for i, frame in enumerate(xyz)]
    Path(path).write_text("\n".join(lines) + "\n")
    return Path(path)


def write_motive_csv(path, labels, xyz, rate, unit="Millimeters", body=None) -> Path:
    """An OptiTrack Motive CSV (format 1.23): a rigid body ``body`` (its name, positions (T, 3)) with
    its solved markers, the labelled markers (T, K, 3), one unlabelled marker; NaN as empty cells."""
    T = xyz.shape[0]
    head, columns = [], []  # head: (type, name, id, quantity, component) per column

    def add(kind, name, ident, quantity, axes, values):
        head.extend((kind, name, ident, quantity, a) for a in axes)
        columns.append(values)

    if body is not None:
        bname, pos = body
        add("Rigid Body", bname, "1", "Rotation", "XYZW", np.tile([0.0, 0.0, 0.0, 1.0], (T, 1)))
        add("Rigid Body", bname, "1", "Position", "XYZ", pos)
        add("Rigid Body", bname, "1", "Mean Marker Error", [""], np.full((T, 1), 0.0002))
        add("Rigid Body Marker", f"{bname}:Marker1", "1", "Position", "XYZ", pos + 5.0)
    for k, label in enumerate(labels):
        add("Marker", label, str(100 + k), "Position", "XYZ", xyz[:, k])
    add("Marker", "Unlabeled 1042", "1042", "Position", "XYZ", np.full((T, 3), 123.0))
    meta = ("Format Version,1.23,Take Name,Take 2024-03-05 10.15.02 AM,Take Notes,,Capture Frame Rate,"
            f"{rate:.6f},Export Frame Rate,{rate:.6f},Capture Start Time,2024-03-05 10.15.02.118 AM,"
            f"Capture Start Frame,0,Total Frames in Take,{T},Total Exported Frames,{T},Rotation Type,Quaternion,"
            f"Length Units,{unit},Coordinate Space,Global")
    rows = list(zip(*head, strict=True))
    lines = [meta, "", ",Type," + ",".join(rows[0]), ",Name," + ",".join(rows[1]), ",ID," + ",".join(rows[2]),
             ",," + ",".join(rows[3]), "Frame,Time (Seconds)," + ",".join(rows[4])]
    table = np.column_stack(columns)
    lines += [f"{i},{i / rate:.6f}," + ",".join(_cell(v) for v in row) for i, row in enumerate(table)]
    Path(path).write_text("\n".join(lines) + "\n")
    return Path(path)


def fitted_values(path) -> dict:
    """Every number a fitted output (calib.yaml, ...) holds, by its place in the file, less the
    provenance (log, command, created) and the optimiser's record (``fit``: its iterations and
    timings): two fits compare without knowing the file's layout."""
    import yaml

    def walk(node, key):
        if isinstance(node, dict):
            for k, v in node.items():
                if key or k not in ("log", "command", "created", "robot", "version", "fit"):
                    yield from walk(v, f"{key}/{k}")
        elif isinstance(node, list):
            for i, v in enumerate(node):
                yield from walk(v, f"{key}/{i}")
        elif isinstance(node, int | float) and not isinstance(node, bool):
            yield key, float(node)

    return dict(walk(yaml.safe_load(Path(path).read_text()), ""))


def run_ok(args):
    """``diegocal ARGS`` through Typer's CliRunner; it must exit 0 (its output is the message)."""
    from typer.testing import CliRunner

    from diegocal.cli import app

    result = CliRunner().invoke(app, [str(a) for a in args])
    assert result.exit_code == 0, result.output
    return result
