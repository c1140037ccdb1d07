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


def test_a_dynamics_model_of_a_robot_with_a_gripper_predicts_with_and_without_robot(tmp_path):
    """The Panda's fingers have torque streams: the fit keeps their joints, and so must predict,
    from --robot or from the model's own copy of the robot (a log that names no robot)."""
    import sys
    from dataclasses import replace

    sys.path.insert(0, str(Path(__file__).parents[1]))
    from erd import robot_dir

    from diegocal.io import save_log
    from experiments.dynamics_generator import Session, generate

    robot = robot_dir(tmp_path, "panda")
    log = tmp_path / "panda.h5"
    save_log(replace(generate(Session(robot="panda", duration=8.0, smooth_scale=0.0)), robot=None), log)
    model = tmp_path / "m.sgp"
    res = runner.invoke(app, ["sgp-fit", str(log), "--robot", str(robot), "--model", "pr", "-o", str(model)])
    assert res.exit_code == 0, res.output
    for extra in (["--robot", str(robot)], []):
        out = tmp_path / f"p{len(extra)}.h5"
        res = runner.invoke(app, ["predict", str(model), str(log), "-o", str(out), *extra])
        assert res.exit_code == 0, res.output
        assert out.is_file()
