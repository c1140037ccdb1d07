"""`diegocal report MODEL --heldout LOG`: a held-out log no model given can be scored on (another
robot's, one without the streams the model needs, one that is not a log) is one clear line and
exit 1, and no PDF is written; a held-out log that fits is used."""

from __future__ import annotations

from dataclasses import replace

import pytest
from typer.testing import CliRunner

from diegocal.cli import app
from diegocal.cli.testing import one_line_error
from diegocal.errors import InputFileError
from diegocal.io import load_log, save_log
from diegocal.report import ReportContext, write_report

runner = CliRunner()


def _report(*args, out):
    return runner.invoke(app, ["report", *map(str, args), "-o", str(out), "-q"])


def test_another_robots_log_is_refused(results, tmp_path):
    """The finger's calibration with the pendulum's log: it used to be dropped silently (exit 0)."""
    out = tmp_path / "r.pdf"
    line = one_line_error(_report(results["kin.calib.yaml"], "--heldout", results["swing_heldout.h5"], out=out))
    assert "swing_heldout.h5" in line and "a log of robot pendulum" in line and "finger" in line, line
    assert not out.exists()


def test_a_log_without_the_streams_the_model_needs_is_refused(results, tmp_path):
    log = load_log(results["kin_heldout.h5"])
    save_log(replace(log, streams={k: v for k, v in log.streams.items() if k != "markers"}), tmp_path / "pots.h5")
    out = tmp_path / "r.pdf"
    line = one_line_error(_report(results["kin.calib.yaml"], "--heldout", tmp_path / "pots.h5", out=out))
    assert "pots.h5" in line and "no markers stream" in line and "kin.calib.yaml" in line, line
    assert not out.exists()


def test_a_held_out_log_beside_no_fitted_model_is_refused(results, tmp_path):
    line = one_line_error(
        _report(results["swing.diagnosis.yaml"], "--heldout", results["swing_heldout.h5"], out=tmp_path / "r.pdf")
    )
    assert "no result given is scored on a held-out log" in line, line


def test_a_held_out_file_that_is_no_log_is_refused(results, tmp_path):
    (tmp_path / "notes.h5").write_text("not a log")
    line = one_line_error(
        _report(results["kin.calib.yaml"], "--heldout", tmp_path / "notes.h5", out=tmp_path / "r.pdf")
    )
    assert "notes.h5" in line, line


def test_each_held_out_log_finds_its_model(results, tmp_path):
    """Three models of three robots with a held-out log each: every log is used, none refused."""
    found = [results["kin.calib.yaml"], results["air.pneumatic.yaml"], results["swing_models"]]
    r = _report(*found, *[a for h in results.heldout for a in ("--heldout", h)], out=tmp_path / "r.pdf")
    assert r.exit_code == 0, r.output
    with pytest.raises(InputFileError, match="a log of robot pendulum"):
        write_report(found[:1], tmp_path / "x.pdf", ReportContext(heldout=(results["swing_heldout.h5"],)))


def test_a_bundled_robot_matches_its_logs_by_folder_name_or_urdf_name():
    """The TX40's URDF calls it staubli_tx40, its folder and its logs tx40: a model of it is scored
    on its held-out log; another robot's log is not."""
    from diegocal.report.registry import robot_matches

    record = {"name": "staubli_tx40", "dir": "/somewhere/robots/tx40"}
    assert robot_matches(record, "tx40") and robot_matches(record, "staubli_tx40")
    assert robot_matches(record, "/somewhere/robots/tx40")
    assert not robot_matches(record, "tiago")
