"""Which robot a log or a fitted model is used with: the one rule every command and the library follow.

A log names its robot (its ``robot`` attribute: a robot directory, a URDF file or a bundled name);
``--robot`` overrides it. A fitted model records the robot it was fitted on (``robot: {name, dir,
hash}`` in its bundle header); a robot whose files differ from those (another hash) is refused.
"""

from __future__ import annotations

from pathlib import Path

from diegocal.errors import DiegocalError, RobotConfigError
from diegocal.io import load_yaml
from diegocal.io.bundle import same_robot
from diegocal.robot.model import data_joints, load_robot, resolve_robot_dir
from diegocal.robot.sensors import parse_sensors


def robot_for_log(robot, data):
    """The robot a command on log ``data`` uses: ``robot`` (a directory, URDF file or bundled
    name; None: the log's own ``robot`` attribute), reduced to the joints the sensors and the
    log's joint streams use (:func:`diegocal.robot.load_robot`)."""
    return load_robot(resolve_robot_dir(robot, data.robot), joints=data_joints(data))


def robot_for_model(record: dict, robot, data, model_path):
    """The robot to use a fitted model on log ``data``: ``robot`` when given, else the log's robot
    when it names one that exists, else the robot the model records (so robots outside robots/
    need no ``--robot``). Refuses, with one line, a robot whose files differ from those the model
    was fitted on (the hash in its header), or a log that names another robot."""
    rec_dir = record.get("dir")
    source, what = None, "--robot"
    if robot is not None:
        source = resolve_robot_dir(robot, None)
    elif data.robot:
        try:
            source, what = resolve_robot_dir(None, data.robot), f"the log's robot ({data.robot})"
        except RobotConfigError:
            known = {record.get("name")} | ({Path(rec_dir).name, Path(rec_dir).stem} if rec_dir else set())
            if data.robot not in known:
                raise RobotConfigError(
                    f"the log is of robot {data.robot!r}, the model {model_path} of {record.get('name')!r}"
                ) from None
    if source is None:
        if not rec_dir or not Path(rec_dir).exists():
            where = f" ({rec_dir} is gone)" if rec_dir else ""
            raise RobotConfigError(f"the log names no robot and neither does the model{where}: pass --robot DIR")
        source, what = Path(rec_dir), "the model's robot"
    if not same_robot(record, source):
        raise RobotConfigError(
            f"{what} {source} is not the robot {model_path} was fitted on ({record.get('name')}, "
            f"{record.get('dir')}): its robot.urdf or sensors.yaml differ (hash {record.get('hash', '')[:15]}…)"
        )
    return load_robot(source, joints=data_joints(data))


def pot_kinds(robot, log_robot: str | None = None) -> dict:
    """{pot: sensors.yaml kind} of a robot (``robot`` and ``log_robot`` as :func:`resolve_robot_dir`
    takes them), read from its sensors.yaml alone; {} when the robot or its sensors.yaml is not found:
    what a report or a table needs to give each pot its unit without loading the URDF."""
    try:
        sensors = parse_sensors(load_yaml(Path(resolve_robot_dir(robot, log_robot)) / "sensors.yaml"))
    except (DiegocalError, OSError, TypeError):
        return {}
    return {p.name: p.kind for p in sensors.pots}
