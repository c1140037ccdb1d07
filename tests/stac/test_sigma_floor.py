"""σ per sensor type never collapses to zero: a group the data do not resolve is held at its
detection limit and said so (qphase.floor_factor); clean logs are untouched."""

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from diegocal.cli import app
from diegocal.io import load_log, load_yaml
from diegocal.robot.resolve import robot_for_log
from diegocal.stac.calibration import Calibration
from diegocal.stac.qphase import floor_factor
from diegocal.stac.result import StacOptions
from diegocal.stac.stac import calibrate

#: the tendon pot fds reads a quadratic curve; the other tendons and both rotary pots are clean
#: (noise 0.005 V): the rotary σ collapsed to the 1e-9 floor before the detection limit
MODEL_ERROR_LOG = Path(__file__).parents[2] / "sample_data" / "finger_hidden_nonlinearity.h5"


def test_floor_factor_acts_only_below_sqrt_2n():
    n = 5000.0
    assert floor_factor(n, 0.5 * n) == 1.0
    assert floor_factor(n, np.sqrt(2 * n) + 1) == 1.0
    assert floor_factor(n, 10.0) == pytest.approx(10.0)  # √10000 / 10


def test_scalar_model_floor_is_one_standard_error_of_the_deleted_residuals():
    """One joint, a pot read against a second sensor: the σ² that the floor holds equals the
    standard error √(2/N) mean(e_del²) of the deleted-residual mean square it is estimated from."""
    rng = np.random.default_rng(3)
    n, s_pot, s_other = 4000, 0.001, 0.02  # the pot far more precise than the other sensor
    q = rng.uniform(-1, 1, n)
    p, o = q + s_pot * rng.standard_normal(n), q + s_other * rng.standard_normal(n)
    branches = set()
    for s in (1e-2, 1e-3):  # a current σ of the pot: its share h of each q and the redundancy r
        h = s_other**2 / (s**2 + s_other**2)
        q_hat = h * p + (1 - h) * o
        e = p - q_hat
        rss, r = np.sum(e * e), n * (1 - h)
        held = rss / r * floor_factor(n, r)
        e_del = e / (1 - h)  # = p − o
        branches.add(bool(r < np.sqrt(2 * n)))
        if r < np.sqrt(2 * n):
            assert held == pytest.approx(np.sqrt(2 / n) * np.mean(e_del**2), rel=1e-9)
        else:
            assert held == pytest.approx(rss / r)
    assert branches == {True, False}


@pytest.fixture(scope="module")
def model_error_fit():
    log = load_log(MODEL_ERROR_LOG)
    robot = robot_for_log(None, log)
    return log, robot, calibrate(log.without_truth(), robot, StacOptions())


def test_rotary_sigma_held_at_detection_limit_not_zero(model_error_fit):
    log, robot, result = model_error_fit
    cal = result.calibration
    assert cal.sigma_by_group["rotary"] > 1e-3  # was 1e-9, a degenerate maximum of eq. 2.5
    assert [u["group"] for u in cal.sigma_unresolved] == ["rotary"]
    # the rotary pots' gains are within a few of their (now honest) standard errors of the truth;
    # with σ at 1e-9 their SEs were 1e-5 of the gain and the errors thousands of them
    truth = Calibration.from_dict(log.truth.params)
    rot = np.array([p.kind == "rotary" for p in robot.sensors.pots])
    z = (cal.gain - truth.gain)[rot] / cal.gain_se[rot]
    assert np.all(np.abs(z) < 4.5), z
    # and σ_rotary came back when written out and read again
    again = Calibration.from_dict(cal.to_dict())
    assert again.sigma_unresolved == cal.sigma_unresolved


def test_clean_finger_sigma_resolved(finger_robot):
    import synth

    log = synth.simulate(finger_robot, 500, seed=21)
    cal = calibrate(log.without_truth(), finger_robot, StacOptions(max_iterations=40)).calibration
    assert cal.sigma_unresolved == ()
    assert cal.sigma_by_group["rotary"] == pytest.approx(0.005, rel=0.3)


def test_cli_says_so_in_one_line(tmp_path):
    out = tmp_path / "f.calib.yaml"
    res = CliRunner().invoke(app, ["stac", str(MODEL_ERROR_LOG), "-o", str(out)])
    assert res.exit_code == 0, res.output
    lines = [ln for ln in res.output.splitlines() if "not resolved by this log" in ln]
    assert len(lines) == 1 and "σ rotary" in lines[0]
    assert load_yaml(out)["sigma"]["unresolved"][0]["group"] == "rotary"
