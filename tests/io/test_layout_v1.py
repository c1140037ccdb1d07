"""Files of layout 1, written by diegocal 0.1.0 (tests/fixtures/v1), still load and predict; the
layout 2 writer keeps every value and standard error of them, now as ``{value, stderr, unit}``."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from diegocal.cli import app
from diegocal.io import load_log, load_yaml
from diegocal.io.bundle import LAYOUT, load_bundle
from diegocal.pneumatic.files import load_model as load_pneumatic
from diegocal.pneumatic.params import NAMES, ChamberParams
from diegocal.sgp.store import load_model as load_dynamics
from diegocal.sgp.store import load_summary, parameters_of
from diegocal.stac.calibration import Calibration
from diegocal.terms import term_from_dict

V1 = Path(__file__).resolve().parents[1] / "fixtures" / "v1"


def test_a_layout_1_calibration_reads_and_rewrites_the_same_numbers():
    raw = load_yaml(V1 / "finger.calib.yaml")
    assert "layout" not in raw and "gain_se" in next(iter(raw["pots"].values()))
    cal = Calibration.from_dict(raw)
    name = cal.pot_names[0]
    assert cal.gain[0] == raw["pots"][name]["gain"] and cal.bias_se[0] == raw["pots"][name]["bias_se"]
    new = cal.to_dict()
    assert new["layout"] == LAYOUT and "pots" not in new
    back = Calibration.from_dict(new)
    np.testing.assert_array_equal(back.gain, cal.gain)
    np.testing.assert_array_equal(back.marker_xyz_se, cal.marker_xyz_se)
    np.testing.assert_allclose(back.mocap_R, cal.mocap_R, atol=1e-14)
    pot = next(t for t in new["baseline"] if t["cause"] == "pot_transfer")
    assert set(pot["parameters"]["gain"]) == {"value", "stderr", "unit"}


def test_a_layout_1_dynamics_model_loads_predicts_and_lists_its_parameters():
    summary = load_summary(V1 / "arm3.sgp")
    params = parameters_of(summary)  # layout 1's ``std`` read as the standard error
    assert params and all(set(p) == {"value", "stderr", "unit"} for p in params.values())
    assert any(name.endswith(".fc") for name in params)
    model = load_dynamics(V1 / "arm3.sgp")
    log = load_log(V1 / "arm3.h5")
    pred = model.predict(log)
    assert pred.tau.shape == log.stream("tau").data.shape and np.isfinite(pred.tau).all()


def test_a_layout_1_diagnosis_and_its_extended_model_load(tmp_path):
    diagnosis = load_bundle(V1 / "arm3.diagnosis.yaml")
    finding = diagnosis.data["findings"][0]
    assert "std" in next(iter(finding["parameters"].values()))
    term = term_from_dict(finding, domain="dynamics")
    assert term.cause == "torque_offset" and np.isfinite(term.parameters[0].stderr)
    extended = load_dynamics(V1 / "arm3.extended.sgp")
    assert [t.cause for t in extended.terms] == ["torque_offset"]
    copy = tmp_path / "v1"
    shutil.copytree(V1, copy)
    out = tmp_path / "pred.h5"
    res = CliRunner().invoke(app, ["predict", str(copy / "arm3.diagnosis.yaml"), str(copy / "arm3.h5"), "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert load_log(out).has("tau")


@pytest.mark.parametrize("name", ["pn.pneumatic.yaml", "pn.extended.pneumatic.yaml"])
def test_a_layout_1_pneumatic_model_reads_and_rewrites_the_same_numbers(name):
    raw = load_yaml(V1 / name)
    model = load_pneumatic(V1 / name)
    chamber, entry = next(iter(raw["chambers"].items()))
    params = model.chambers[chamber].params
    assert params.values == {n: entry[n] for n in NAMES}
    new = params.to_dict(chamber)
    assert "c1" not in new and [t["cause"] for t in new["baseline"]][0] == "valve_steady_state"
    back = ChamberParams.from_dict(new)
    assert back.values == params.values and back.stderr == pytest.approx(params.stderr, nan_ok=True)
    np.testing.assert_array_equal(back.full_vector(), params.full_vector())
