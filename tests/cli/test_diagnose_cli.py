"""`diegocal diagnose` from the command line: bad input is one line and a non-zero exit, never a
traceback and never a half-written output."""

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from diegocal.cli import app
from diegocal.cli.testing import one_line_error
from diegocal.io import Log, make_stream, save_log

runner = CliRunner()


def _log(tmp_path: Path, streams: dict, robot: str | None = "diego", T: int = 200) -> Path:
    path = tmp_path / "run.h5"
    log = Log(
        np.arange(T) * 0.01,
        {k: make_stream(names, np.random.default_rng(0).normal(size=(T, len(names)))) for k, names in streams.items()},
        robot=robot,
        rate_hz=100.0,
    )
    save_log(log, path)
    return path


def _no_outputs(tmp_path: Path) -> bool:
    return not list(tmp_path.glob("*diagnosis*")) and not list(tmp_path.glob("*extended*"))


def test_a_missing_log_is_one_line(tmp_path):
    line = one_line_error(runner.invoke(app, ["diagnose", str(tmp_path / "nope.h5")]))
    assert "nope.h5" in line


def test_a_log_with_no_diagnosable_streams_names_what_it_needs(tmp_path):
    path = _log(tmp_path, {"qd": ["joint1"]}, robot="arm3")
    result = runner.invoke(app, ["diagnose", str(path)])
    assert result.exit_code == 1
    line = one_line_error(result)
    assert "nothing to diagnose" in line and "q + tau" in line and "qd" in line
    assert _no_outputs(tmp_path)


def test_a_domain_whose_streams_are_missing_is_one_line(tmp_path):
    path = _log(tmp_path, {"q": ["joint1"], "tau": ["joint1"]}, robot="arm3")
    result = runner.invoke(app, ["diagnose", str(path), "--domain", "pneumatics"])
    assert result.exit_code == 1
    assert "pressure" in one_line_error(result)
    assert _no_outputs(tmp_path)


def test_an_unknown_domain_is_a_usage_error(tmp_path):
    path = _log(tmp_path, {"q": ["joint1"], "tau": ["joint1"]}, robot="arm3")
    result = runner.invoke(app, ["diagnose", str(path), "--domain", "thermal"])
    assert result.exit_code == 2
    assert "thermal" in one_line_error(result)


@pytest.mark.parametrize(
    "option", [["--friction", "sticky"], ["--alpha", "2"], ["--blocks", "1"], ["--inertia", "guessed"]]
)
def test_bad_option_values_are_usage_errors(tmp_path, option):
    path = _log(tmp_path, {"q": ["joint1"], "tau": ["joint1"]}, robot="arm3")
    result = runner.invoke(app, ["diagnose", str(path), *option])
    assert result.exit_code == 2
    one_line_error(result)


def test_an_unknown_chamber_is_one_line(tmp_path):
    path = _log(tmp_path, {"pressure": ["r_elbow.flex"], "valve": ["r_elbow.flex"], "pots": ["r_elbow"]})
    result = runner.invoke(app, ["diagnose", str(path), "--chamber", "r_elbo.flex"])
    assert result.exit_code == 1
    assert "r_elbo.flex" in one_line_error(result)
    assert _no_outputs(tmp_path)


def test_a_log_naming_no_robot_asks_for_one(tmp_path):
    path = _log(tmp_path, {"q": ["joint1"], "tau": ["joint1"]}, robot=None)
    result = runner.invoke(app, ["diagnose", str(path)])
    assert result.exit_code == 1
    assert "--robot" in one_line_error(result)


def test_the_summary_says_which_gain_and_what_stood_in_for_an_unexplained_chamber():
    from types import SimpleNamespace

    from diegocal.cli.diagnose_cmd import _summary_rows

    finding = {
        "cause": "unexplained",
        "channel": "elbow.ext",
        "gain": {},
        "evidence": {
            "validation_gain": 0.77,
            "stand_in": {"term": "supply_droop:elbow.ext", "validation_gain": 0.2},
            "rival": {"model": "the pressure read through a first-order filter (τ 45 ms)"},
        },
    }
    mapping = {
        "baseline": {"model": "c1..c9", "heldout_rmse": {"elbow.ext": 15.7}, "units": {"elbow.ext": "kPa"}},
        "extended": {"heldout_rmse": {"elbow.ext": 15.7}},
        "findings": [finding],
    }
    rows = dict(_summary_rows(SimpleNamespace(domain="pneumatics", mapping=mapping, output="d.yaml", extended="e")))
    text = rows["  unexplained on elbow.ext"]
    assert text == "open-loop validation gain 77% (not explained by any term; supply_droop:elbow.ext stood in)"


def test_a_log_marker_the_robot_does_not_name_is_said_once(tmp_path):
    """A marker renamed in the mocap file: the diagnosis binds the log to the robot more than once,
    and each warning line had been printed as often; every line is said once per command."""
    from diegocal.io import Stream
    from diegocal.robot import load_robot, resolve_robot_dir
    from diegocal.sim.kinematics import KinematicsOptions, simulate_kinematics

    finger = load_robot(resolve_robot_dir("finger", None))
    log = simulate_kinematics(finger, KinematicsOptions(duration=5.0), np.random.default_rng(3))
    st = log.stream("markers")
    names = list(st.names)
    names[1] += "_x"
    save_log(log.with_streams(markers=Stream(tuple(names), st.data)), tmp_path / "ren.h5")
    out = tmp_path / "ren.diagnosis.yaml"
    args = ["diagnose", str(tmp_path / "ren.h5"), "--domain", "kinematics", "-o", str(out), "-q"]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    assert result.output.count(f"ignored 1 log markers ({names[1]})") == 1
    assert result.output.count(f"not calibrated: {st.names[1]}") == 1


def test_a_batch_job_collects_each_warning_once_and_the_library_after_a_command_says_all():
    """The once-per-command rule holds for a batch job's collected warnings too, and leaves no state
    behind: library calls after a command (or outside one) say every warning."""
    import logging

    from diegocal.cli.common import collected_warnings

    log = logging.getLogger("diegocal.test")
    with collected_warnings() as lines:
        log.warning("same")
        log.warning("same")
        log.warning("other")
    assert lines == ["same", "other"]
    result = runner.invoke(app, ["diagnose", "nope.h5"])
    assert result.exit_code == 1
    with collected_warnings() as lines:
        log.warning("same")
    assert lines == ["same"]
