"""What the batch table and its page say (user trial on a robot with an encoder): each sensor type's
σ and every parameter in its own unit (an encoder's in rad; no pooled 'sigma pots [V]'); no output
named for a log that failed; a prediction's columns are predictions only, each with its unit (no
'pots RMSE' of pots predicted from pots); the logs the command cannot use are listed, with why, in
the table and on its page as on the terminal."""

from __future__ import annotations

import re
from pathlib import Path

import pymupdf
import pytest
from typer.testing import CliRunner

from diegocal.batch import read_table
from diegocal.cli import app
from tests.report.encoder_arm import make_robot, save_session

runner = CliRunner()
NOTES = "what,when\nnew cable,monday\n"


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    """Two sessions of the encoder arm, a truncated log (fails) and a lab's notes (not applicable)."""
    d = tmp_path_factory.mktemp("trial")
    robot = make_robot(d / "arm")
    logs = d / "logs"
    logs.mkdir()
    for seed in (1, 2):
        save_session(robot, logs / f"s{seed}.h5", seed=seed, duration=6.0)
    (logs / "s3_truncated.h5").write_bytes((logs / "s1.h5").read_bytes()[:4000])
    (logs / "notes.csv").write_text(NOTES)
    return logs


@pytest.fixture(scope="module")
def stac_out(folder, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("cal")
    r = runner.invoke(app, ["batch", "stac", str(folder), "-o", str(out), "-q"])
    assert r.exit_code == 1, r.output  # the truncated log failed
    return out


def _rows(table: Path) -> tuple[list[str], dict]:
    _, columns, rows = read_table(table)
    return columns, {Path(r["log"]).name: r for r in rows}


def test_stac_columns_each_in_their_sensors_unit(stac_out):
    """Trial item 1: 'bias enc6 [V]', and 'sigma pots [V]' = 0.00181 matching neither type's σ."""
    columns, rows = _rows(stac_out / "stac.batch.csv")
    sigma = [c for c in columns if c.startswith("sigma")]
    assert sigma == ["sigma rotary [V]", "sigma encoder [rad]", "sigma markers [m]"]
    assert "bias wrist [rad]" in columns and "bias elbow [V]" in columns and "gain elbow [V/rad]" in columns
    assert not [c for c in columns if c.startswith("gain wrist")]  # 1 by design, not a parameter
    for c in columns[columns.index("converged") + 1 :]:
        assert re.search(r" \[[^]]+\]$", c), f"column {c!r} has no unit"
    assert 0.001 < float(rows["s1.h5"]["sigma rotary [V]"]) < 0.01


def test_a_failed_log_names_no_output_and_a_file_not_applicable_is_listed(stac_out):
    """Trial item 3: 'batchcal/s5_truncated.calib.yaml' named though never written; the batch page
    left out the not-applicable file the terminal named."""
    _, rows = _rows(stac_out / "stac.batch.csv")
    assert rows["s3_truncated.h5"]["status"] == "failed" and rows["s3_truncated.h5"]["output"] == ""
    assert not (stac_out / "s3_truncated.calib.yaml").exists()
    assert rows["s1.h5"]["output"] == str(stac_out / "s1.calib.yaml")
    notes = rows["notes.csv"]
    assert notes["status"] == "not applicable" and "not a diegocal CSV log" in notes["reason"]
    assert notes["output"] == ""
    text = " ".join(" ".join(p.get_text().split()) for p in pymupdf.open(stac_out / "stac.batch.pdf"))
    assert "Not run, as not applicable: notes.csv: not a diegocal CSV log" in text
    assert "ran over 3 log(s)" in text  # the notes are no log it ran over


def test_predict_columns_are_predictions_with_units(folder, stac_out, tmp_path):
    """Trial item 3: 'pots RMSE' 2.7e-17, no unit, for --from pots (pots predicted from pots)."""
    model = stac_out / "s1.calib.yaml"
    out = tmp_path / "pred"
    r = runner.invoke(app, ["batch", "predict", str(folder), "--model", str(model), "-o", str(out), "-q"])
    assert r.exit_code == 1, r.output
    columns, rows = _rows(out / "predict.batch.csv")
    errors = columns[columns.index("warnings") + 1 :]
    assert errors == ["markers mean distance [m]"]  # --from pots --to markers: the pots are no prediction
    assert float(rows["s2.h5"]["markers mean distance [m]"]) < 0.01
    assert rows["s3_truncated.h5"]["output"] == "" and rows["notes.csv"]["status"] == "not applicable"
    out = tmp_path / "pred_pots"
    argv = ["batch", "predict", str(folder), "--model", str(model), "-o", str(out), "-q"]
    r = runner.invoke(app, [*argv, "--", "--from", "markers", "--to", "pots,markers"])
    columns, rows = _rows(out / "predict.batch.csv")
    errors = columns[columns.index("warnings") + 1 :]
    assert errors == ["rotary RMSE [V]", "encoder RMSE [rad]"]  # markers were the source: not predicted
    assert 0 < float(rows["s2.h5"]["encoder RMSE [rad]"]) < 0.5
