"""Robot models: URDF through Pinocchio, sensors.yaml, observation models and their Jacobians."""

from diegocal.robot.gauges import gauge_joints
from diegocal.robot.model import BUNDLED_ROBOTS, PointSet, Robot, data_joints, load_robot, resolve_robot_dir
from diegocal.robot.observe import (
    anchor_points,
    marker_points,
    markers_jacobian,
    pot_transmission,
    pot_transmission_jacobian,
    pots_jacobian,
    predict_markers,
    predict_pots,
)
from diegocal.robot.sensors import (
    POT_KINDS,
    Anchor,
    ChamberSpec,
    MarkerSpec,
    PotSpec,
    SensorConfig,
    parse_sensors,
)

__all__ = [
    "BUNDLED_ROBOTS",
    "POT_KINDS",
    "Anchor",
    "ChamberSpec",
    "MarkerSpec",
    "PointSet",
    "PotSpec",
    "Robot",
    "SensorConfig",
    "anchor_points",
    "data_joints",
    "gauge_joints",
    "load_robot",
    "marker_points",
    "markers_jacobian",
    "parse_sensors",
    "pot_transmission",
    "pot_transmission_jacobian",
    "pots_jacobian",
    "predict_markers",
    "predict_pots",
    "resolve_robot_dir",
]
