"""`diegocal stac` on a fit that stops before it converges (#31 item 6, #32): the calibration is
written with ``converged: false``, a warning says so in words, and the exit status is 1 unless
``--allow-unconverged``."""

import numpy as np
import pytest
from typer.testing import CliRunner

from diegocal.cli import app
from diegocal.io import load_yaml, save_log
from diegocal.robot import load_robot, resolve_robot_dir
from diegocal.sim.kinematics import KinematicsOptions, simulate_kinematics

runner = CliRunner()


@pytest.fixture(scope="module")
def finger_log(tmp_path_factory):
    """`diegocal simulate kinematics --robot finger --duration 10 --seed 1`, as the issue has it."""
    path = tmp_path_factory.mktemp("finger") / "f.h5"
    robot = load_robot(resolve_robot_dir("finger", None))
    save_log(simulate_kinematics(robot, KinematicsOptions(duration=10.0), np.random.default_rng(1)), path)
    return path


def test_an_unconverged_fit_exits_1_and_says_so(finger_log, tmp_path):
    out = tmp_path / "f.calib.yaml"
    r = runner.invoke(app, ["stac", str(finger_log), "--max-iterations", "2", "-o", str(out)])
    assert r.exit_code == 1
    assert "warning: the stac fit did not converge: it stopped after 2 iteration(s)" in " ".join(r.output.split())
    assert "--allow-unconverged" in r.output and "Traceback" not in r.output
    assert load_yaml(out)["fit"]["converged"] is False  # written, and marked


def test_allow_unconverged_exits_0_with_the_warning(finger_log, tmp_path):
    out = tmp_path / "f.calib.yaml"
    r = runner.invoke(app, ["stac", str(finger_log), "--max-iterations", "2", "-o", str(out), "-q",
                            "--allow-unconverged"])
    assert r.exit_code == 0, r.output
    assert "did not converge" in r.output and load_yaml(out)["fit"]["converged"] is False


def test_a_method_that_does_not_iterate_is_not_unconverged(finger_log, tmp_path):
    r = runner.invoke(app, ["stac", str(finger_log), "--method", "nominal", "-o", str(tmp_path / "n.yaml"), "-q"])
    assert r.exit_code == 0 and "converge" not in r.output, r.output
