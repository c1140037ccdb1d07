"""FIGAROH's calibration on one fold, run in FIGAROH's own environment (it imports no diegocal):
``FIGAROH_PYTHON bench/figaroh_driver.py JOB_DIR``, called by ``bench_static_calibration.py``.

JOB_DIR holds ``job.json`` ({urdf, joints, tool_frame, level: full_params | joint_offset,
points}), ``train.csv`` and ``test.csv`` in FIGAROH's CSV layout (x1, y1, z1, ... per point and
one column per active joint). FIGAROH 1.0.2's ``BaseCalibration`` is configured by a unified
config written here (base frame unknown, the tool points' positions estimated) and solved with
its defaults; the held-out points are ``calc_updated_fkm`` at the test rows' joint angles. Writes
``pred.npy`` (N, points, 3) m and ``seconds.txt``.
"""

from __future__ import annotations

import json
import sys
import time
from contextlib import redirect_stdout
from pathlib import Path

import numpy as np
import pinocchio as pin
import yaml
from figaroh.calibration.base_calibration import BaseCalibration
from figaroh.calibration.calibration_tools import calc_updated_fkm
from figaroh.data.observations import PoseObservations
from pinocchio.robot_wrapper import RobotWrapper


def main(job_dir: str) -> None:
    d = Path(job_dir)
    job = json.loads((d / "job.json").read_text())
    config = {
        "meta": {"schema_version": "2.0"},
        "robot": {"name": "robot"},
        "tasks": {
            "calibration": {
                "type": "kinematic_calibration",
                "kinematics": {"base_frame": "universe", "tool_frame": job["tool_frame"]},
                "joints": {"active_joints": job["joints"]},
                "measurements": {
                    "markers": [{"measurable_dof": [True, True, True, False, False, False]}] * job["points"],
                    "poses": {"base_pose": None, "tool_pose": None},
                },
                "parameters": {"calibration_level": job["level"]},
                "data": {"source_file": str(d / "train.csv")},
            }
        },
    }
    (d / "config.yaml").write_text(yaml.safe_dump(config))
    robot = RobotWrapper(pin.buildModelFromUrdf(job["urdf"]))  # the kinematics alone (no meshes)
    t0 = time.perf_counter()
    calib = BaseCalibration(robot, str(d / "config.yaml"))
    calib.calib_config["known_baseframe"] = False  # the mocap frame is estimated
    calib.calib_config["known_tipframe"] = False  # and the tool points on the tool frame
    calib.initialize()
    with open(d / "figaroh.log", "w") as log, redirect_stdout(log):  # its quality report
        calib.solve(enable_logging=False, plotting=False, save_results=False)
    seconds = time.perf_counter() - t0
    test = PoseObservations.from_csv(d / "test.csv", robot.model, calib.calib_config)
    _, q = test.to_legacy(robot.model, calib.calib_config)
    model = pin.Model(robot.model)
    config = dict(calib.calib_config, NbSample=q.shape[0])  # it loops over NbSample rows
    flat = calc_updated_fkm(model, model.createData(), calib.var_, q, config)
    pred = np.asarray(flat).reshape(job["points"], 3, -1).transpose(2, 0, 1)
    np.save(d / "pred.npy", pred)
    (d / "seconds.txt").write_text(f"{seconds}\n")


if __name__ == "__main__":
    main(sys.argv[1])
