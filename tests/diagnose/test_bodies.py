"""A payload no body can be is named ``link_inertia`` (diegocal.diagnose.bodies): the judgement on
numbers, the simulator's link whose URDF inertias are too large (a true payload left alone:
tests/diagnose/test_dynamics.py's payload tests), a parameter the data do not identify written
with no value and read back so."""

from __future__ import annotations

import math

import numpy as np
import pytest
from typer.testing import CliRunner

from diegocal.cli import app
from diegocal.diagnose import DiagnoseOptions, diagnose
from diegocal.diagnose.bodies import BODY_Z, impossible_body, restate
from diegocal.io import save_log
from diegocal.io.bundle import load_bundle
from diegocal.robot import load_robot
from diegocal.robot.model import BUNDLED_ROBOTS
from diegocal.sgp.store import load_model
from diegocal.sim.dynamics import DynamicsOptions, simulate_dynamics
from diegocal.terms import Parameter, make_term, read_parameter

NAMES = ("mass", "mc_x", "mc_y", "mc_z", "I_xx", "I_xy", "I_yy", "I_xz", "I_yz", "I_zz")


def body(values, stderr=0.01) -> dict:
    """name -> (value, standard error) in the payload's order."""
    se = stderr if isinstance(stderr, (list, tuple)) else [stderr] * 10
    return dict(zip(NAMES, zip(values, se, strict=True), strict=True))


def point_mass(m, c) -> list:
    """The ten parameters of a point mass m at c about the joint (second moments m(|c|²1 − ccᵀ))."""
    c = np.asarray(c, float)
    I = m * (c @ c * np.eye(3) - np.outer(c, c))  # noqa: E741
    return [m, *(m * c), I[0, 0], I[0, 1], I[1, 1], I[0, 2], I[1, 2], I[2, 2]]


def test_a_point_mass_and_a_solid_body_are_bodies():
    assert impossible_body(body(point_mass(0.5, [0.1, -0.2, 0.05]), 0.0), BODY_Z) == ""
    solid = np.array(point_mass(2.0, [0.3, 0.0, 0.1])) + np.array([0, 0, 0, 0, 0.01, 0, 0.02, 0, 0, 0.01])
    assert impossible_body(body(solid), BODY_Z, reach=1.0) == ""


def test_a_small_mass_far_out_is_no_body():
    """TIAGo's arm_3_link against the URDF's inertias: 0.078 kg whose first moment puts it 7 m out,
    with second moments a third too small for that."""
    fit = body([0.078, -0.0038, -0.0497, 0.559, 3.07, 0.72, 2.22, 0.79, -0.31, 0.17],
               [0.00076, 0.0024, 0.003, 0.0051, 0.14, 0.086, 0.14, 0.073, 0.084, 0.094])
    far = impossible_body(fit, BODY_Z, reach=1.37)
    assert "centre of mass" in far and "1.37 m" in far
    assert "I_xx" in impossible_body(fit, BODY_Z)  # with any reach: too little second moment


def test_moments_short_of_the_mass_beyond_their_errors_are_no_body():
    fit = point_mass(1.0, [0.0, 0.0, 0.5])  # I_xx = I_yy = 0.25
    fit[4] = 0.25 - 10 * 0.01
    assert "I_xx" in impossible_body(body(fit), BODY_Z)
    fit[4] = 0.25 - 2 * 0.01  # within BODY_Z standard errors of a body
    assert impossible_body(body(fit), BODY_Z) == ""


def test_without_an_identified_mass_only_the_second_moments_sign_is_judged():
    """The TX40's link_2 against the URDF's inertias (mass and m·c_z not identified): a body; the
    same with I_zz well below zero (a link lighter than its URDF) is none."""
    values = [math.nan, -0.3, 0.17, math.nan, 0.58, 0.0, 0.63, 0.0, 0.0, 0.59]
    se = [math.nan, 0.015, 0.023, math.nan, 0.0075, 0.005, 0.006, 0.005, 0.004, 0.0095]
    assert impossible_body(body(values, se), BODY_Z, reach=1.0) == ""
    values[9] = -0.59
    assert "I_zz is below zero" in impossible_body(body(values, se), BODY_Z, reach=1.0)


def test_a_zero_standard_error_does_not_hide_a_negative_mass():
    fit = make_term("payload", "link3", point_mass(-0.2, [0.1, 0, 0]), stderr=[0.0] * 10)
    assert restate(fit, 1.0)[0].cause == "link_inertia"


def test_the_extent_reaches_a_bodys_centre_of_mass():
    """The pendulum's bob hangs 0.5 m out on its only joint, with no frame there."""
    assert load_robot(BUNDLED_ROBOTS / "pendulum").extent("bob") >= 0.5


def test_a_value_the_data_do_not_identify_is_written_null_and_read_back_as_none():
    d = Parameter("mass", math.nan, "kg").to_dict()
    assert d["value"] is None and d["stderr"] is None
    assert math.isnan(read_parameter("mass", d).value)


def test_restate_names_the_link_for_a_negative_mass_and_leaves_a_body_alone():
    payload = make_term("payload", "link3", point_mass(-0.24, [0.125, 0, 0]), stderr=[0.001] * 10)
    link, why = restate(payload, 1.0)
    assert (link.cause, link.channel) == ("link_inertia", "link3")
    assert "below zero" in why and "own inertias" in why
    assert restate(make_term("payload", "link3", point_mass(0.3, [0.1, 0, 0]), stderr=[0.001] * 10), 1.0) is None
    assert restate(make_term("torque_offset", "joint1", [-5.0], stderr=[0.1]), 1.0) is None


@pytest.fixture(scope="module")
def arm3():
    return load_robot(BUNDLED_ROBOTS / "arm3")


def test_a_link_whose_urdf_is_too_heavy_is_named_link_inertia_with_the_change(arm3):
    """The simulator's link3 is 30 % lighter than the URDF (every inertial parameter): against the
    URDF's inertias the one finding is ``link_inertia`` on link3, not a payload, with the truth's
    change within 4 standard errors on each identified parameter, and the baseline's error gone."""
    log = simulate_dynamics(arm3, DynamicsOptions(duration=30.0, effects=("link_inertia:link3=0.3",)),
                            np.random.default_rng(3))
    d = diagnose(log, arm3, DiagnoseOptions(domain="dynamics", inertia="nominal"))
    assert [(f.cause, f.channel) for f in d.findings] == [("link_inertia", "link3")]
    (f,) = d.findings
    assert "below zero" in f.evidence["restated"]
    (truth,) = log.truth.effects
    seen = 0
    for p in f.term.parameters:
        if np.isfinite(p.stderr):
            seen += 1
            assert abs(p.value - truth["values"][p.name]) < max(4 * p.stderr, 1e-3 * abs(truth["values"]["mass"])), p
    assert seen >= 6
    assert d.units[0].extended_score.pooled_rmse() < 1.2 * 0.01


def test_a_link_cannot_lose_all_its_inertia(arm3):
    from diegocal.sim.effects import SimOptionError

    with pytest.raises(SimOptionError, match="0 < fraction < 1"):
        simulate_dynamics(arm3, DynamicsOptions(duration=2.0, effects=("link_inertia:link3=1.5",)),
                          np.random.default_rng(0))


def test_a_payload_whose_mass_is_not_identified_has_no_value_in_either_file(arm3, tmp_path):
    """link2's origin lies on joint1's axis: its mass shows in no torque. The diagnosis and the
    saved extended model write it null, and the model read back gives it no value."""
    log = simulate_dynamics(arm3, DynamicsOptions(duration=20.0, effects=("payload:link2=0.5",)),
                            np.random.default_rng(5))
    path = tmp_path / "run.h5"
    save_log(log, path)
    out = str(tmp_path / "d.yaml")
    args = ["diagnose", str(path), "--inertia", "nominal", "--robot", str(arm3.directory), "-o", out]
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 0, res.output
    (finding,) = [f for f in load_bundle(tmp_path / "d.yaml").data["findings"] if f["cause"] == "payload"]
    assert finding["parameters"]["mass"]["value"] is None
    saved = load_bundle(tmp_path / "d.extended.sgp").data["terms"]
    assert saved[0]["parameters"]["mass"] == {"value": None, "stderr": None, "unit": "kg"}
    (term,) = load_model(tmp_path / "d.extended.sgp").fitted_terms()
    assert math.isnan(term.value("mass")) and np.isfinite(term.value("I_zz"))
    res = CliRunner().invoke(app, ["report", str(tmp_path / "d.extended.sgp"), "-o", str(tmp_path / "r.pdf")])
    assert res.exit_code == 0, res.output
