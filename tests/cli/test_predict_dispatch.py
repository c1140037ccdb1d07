"""predict dispatches on a model's bundle kind (one loader), and a diagnosis stands for its
extended model."""

from pathlib import Path

import pytest
import yaml
from typer.testing import CliRunner

from diegocal.cli import app
from diegocal.errors import InputFileError
from diegocal.predict import resolve_model

runner = CliRunner()


def _write(path: Path, mapping: dict) -> Path:
    path.write_text(yaml.safe_dump(mapping))
    return path


@pytest.mark.parametrize(
    "mapping, predictor",
    [
        ({"kind": "calibration", "pots": {}}, "kinematics"),
        ({"kind": "pneumatic", "chambers": {}}, "pneumatics"),
        ({"pots": {}, "markers": {}}, "kinematics"),  # a calib.yaml written before the header existed
    ],
)
def test_the_predictor_follows_the_bundle_kind(tmp_path, mapping, predictor):
    path = _write(tmp_path / "model.yaml", mapping)
    assert resolve_model(path) == (predictor, path)


def test_a_diagnosis_resolves_to_its_extended_model(tmp_path):
    extended = _write(tmp_path / "run.extended.pneumatic.yaml", {"kind": "pneumatic", "chambers": {}})
    diagnosis = _write(
        tmp_path / "run.diagnosis.yaml",
        {"kind": "diagnosis", "domain": "pneumatics", "findings": [], "extended_model": extended.name},
    )
    assert resolve_model(diagnosis) == ("pneumatics", extended)


def test_a_diagnosis_without_an_extended_model_is_an_error(tmp_path):
    diagnosis = _write(tmp_path / "d.yaml", {"kind": "diagnosis", "domain": "dynamics", "findings": []})
    with pytest.raises(InputFileError, match="names no extended model"):
        resolve_model(diagnosis)


def test_a_yaml_that_is_no_model_is_one_line_and_exit_1(tmp_path):
    path = _write(tmp_path / "notes.yaml", {"a": 1})
    log = tmp_path / "run.h5"
    log.write_bytes(b"")
    result = runner.invoke(app, ["predict", str(path), str(log)])
    assert result.exit_code == 1
    assert "not a fitted diegocal model" in result.output
    assert "Traceback" not in result.output
