"""Small real results of every kind, made once for the report's tests (seeded): a log, a
calibration, pneumatic models, a comparison of two torque models (pr and sgp), a torque prediction
on a held-out log, a diagnosis, with held-out logs of the same robots."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from diegocal.cli import app
from diegocal.io import save_log
from diegocal.robot import load_robot, resolve_robot_dir
from diegocal.sim.dynamics import DynamicsOptions, simulate_dynamics
from diegocal.sim.kinematics import KinematicsOptions, simulate_kinematics
from diegocal.sim.pneumatics import PneumaticSimOptions, simulate_pneumatics
from tests.pneumatic.conftest import SENSORS, URDF

runner = CliRunner()


def cli(*args):
    """Run diegocal with ``args``; the run must succeed."""
    r = runner.invoke(app, [str(a) for a in args])
    assert r.exit_code == 0, r.output
    return r


@dataclass(frozen=True)
class Results:
    """The results (in the order a report takes them) and their held-out logs, by name."""

    folder: Path
    found: list[Path]
    heldout: list[Path]

    def __getitem__(self, name: str) -> Path:
        return self.folder / name


@pytest.fixture(scope="session")
def results(tmp_path_factory) -> Results:
    d = tmp_path_factory.mktemp("results")
    finger = load_robot(resolve_robot_dir("finger", None))
    session = simulate_kinematics(finger, KinematicsOptions(duration=6.0), np.random.default_rng(4))
    split = 400
    save_log(session.slice(0, split), d / "kin.h5")
    save_log(session.slice(split, session.n_samples), d / "kin_heldout.h5")
    pendulum = load_robot(resolve_robot_dir("pendulum", None))
    for name, seed in (("swing.h5", 1), ("swing_heldout.h5", 2)):
        save_log(simulate_dynamics(pendulum, DynamicsOptions(duration=4.0), np.random.default_rng(seed)), d / name)
    cli("stac", d / "kin.h5", "-o", d / "kin.calib.yaml", "-q")
    (d / "swing_models").mkdir()
    for kind in ("pr", "sgp"):
        cli("sgp-fit", d / "swing.h5", "--model", kind, "-o", d / "swing_models" / f"{kind}.sgp", "-q")
    cli("predict", d / "swing_models" / "sgp.sgp", d / "swing_heldout.h5", "-o", d / "swing.prediction.h5", "-q")
    cli("diagnose", d / "swing.h5", "-o", d / "swing.diagnosis.yaml", "-q")
    robot_dir = d / "tiny_pneu"
    robot_dir.mkdir()
    (robot_dir / "robot.urdf").write_text(URDF)
    (robot_dir / "sensors.yaml").write_text(SENSORS)
    tiny = load_robot(robot_dir)
    for name, seed in (("air.h5", 1), ("air_heldout.h5", 2)):
        save_log(simulate_pneumatics(tiny, PneumaticSimOptions(duration=6.0, seed=seed)), d / name)
    cli("pneumatic-fit", d / "air.h5", "--robot", robot_dir, "--all", "-o", d / "air.pneumatic.yaml", "-q")
    found = [d / "kin.h5", d / "kin.calib.yaml", d / "air.pneumatic.yaml", d / "swing_models"]
    found += [d / "swing.prediction.h5", d / "swing.diagnosis.yaml"]
    return Results(d, found, [d / "kin_heldout.h5", d / "swing_heldout.h5", d / "air_heldout.h5"])
