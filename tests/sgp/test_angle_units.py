"""Joint angles in degrees where the log wants rad (user trial: `diagnose --domain dynamics` gave five
confident findings): where q is read for a robot (:func:`diegocal.sgp.streams.check_angles`, from
``log_arrays`` and ``DynamicsModel.fit_arrays``) a revolute joint far outside its URDF limits, and
within them read as degrees, is one error line for sgp-fit, predict and diagnose; a small excursion
is one warning line; continuous and prismatic joints are not checked; real logs pass."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from diegocal.cli import app
from diegocal.cli.testing import one_line_error
from diegocal.errors import LogFormatError
from diegocal.io import load_log, make_stream, save_log
from diegocal.robot import load_robot
from diegocal.robot.resolve import robot_for_log
from diegocal.sgp.streams import check_angles, log_arrays
from tests.sgp.conftest import write_robot

SAMPLE = Path(__file__).resolve().parents[2] / "sample_data"
HINT = "degrees? the log wants rad"
runner = CliRunner()

#: a continuous joint, a prismatic one (m) and a revolute one with limits
MIXED_URDF = """<?xml version="1.0"?>
<robot name="mixed">
  <link name="base"/>
  <link name="a"><inertial><origin xyz="0.1 0 0"/><mass value="1.0"/>
    <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/></inertial></link>
  <link name="b"><inertial><origin xyz="0.1 0 0"/><mass value="1.0"/>
    <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/></inertial></link>
  <link name="c"><inertial><origin xyz="0.1 0 0"/><mass value="1.0"/>
    <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/></inertial></link>
  <joint name="spin" type="continuous"><parent link="base"/><child link="a"/><axis xyz="0 0 1"/></joint>
  <joint name="slide" type="prismatic"><parent link="a"/><child link="b"/><axis xyz="1 0 0"/>
    <limit lower="0" upper="0.3" effort="50" velocity="1"/></joint>
  <joint name="elbow" type="revolute"><parent link="b"/><child link="c"/><axis xyz="0 1 0"/>
    <limit lower="-2.0" upper="2.0" effort="50" velocity="10"/></joint>
</robot>
"""


def _degrees(log):
    """The same log with q, qd, qdd in degrees (tau unchanged)."""
    s = log.streams
    return log.with_streams(**{k: make_stream(s[k].names, np.degrees(s[k].data)) for k in ("q", "qd", "qdd")})


@pytest.fixture
def logs(arm2, simulate, tmp_path):
    good, _ = simulate(arm2, T=120, seed=7)
    paths = tmp_path / "good.h5", tmp_path / "deg.h5"
    save_log(good, paths[0])
    save_log(_degrees(good), paths[1])
    return paths


def test_sgp_fit_refuses_degrees_in_one_line(logs, arm2_dir):
    _, deg = logs
    out = deg.with_name("deg.sgp")
    res = runner.invoke(app, ["sgp-fit", str(deg), "--robot", str(arm2_dir), "-m", "pr", "-o", str(out)])
    assert res.exit_code == 1
    line = one_line_error(res)
    assert HINT in line and ("joint 'shoulder'" in line or "joint 'elbow'" in line)
    assert "far outside its URDF limits" in line and not out.exists()


def test_predict_and_diagnose_refuse_degrees(logs, arm2_dir, tmp_path):
    good, deg = logs
    model = tmp_path / "good.sgp"
    res = runner.invoke(app, ["sgp-fit", str(good), "--robot", str(arm2_dir), "-m", "pr", "-o", str(model), "-q"])
    assert res.exit_code == 0, res.output
    assert "URDF limits" not in res.output  # a log in rad: neither error nor warning
    pred = tmp_path / "pred.h5"
    res = runner.invoke(app, ["predict", str(model), str(deg), "--robot", str(arm2_dir), "-o", str(pred), "-q"])
    assert res.exit_code == 1 and HINT in one_line_error(res) and not pred.exists()
    diag = tmp_path / "deg.diagnosis.yaml"
    res = runner.invoke(app, ["diagnose", str(deg), "--domain", "dynamics", "--robot", str(arm2_dir), "-o", str(diag)])
    assert res.exit_code == 1 and "Traceback" not in res.output
    assert HINT in res.output.strip().splitlines()[-1]
    assert not diag.exists() and not list(tmp_path.glob("*extended*"))


@pytest.fixture(scope="module")
def mixed(tmp_path_factory):
    return load_robot(write_robot(tmp_path_factory.mktemp("mixed"), MIXED_URDF))


def test_continuous_and_prismatic_joints_are_not_checked(mixed, caplog):
    assert mixed.joint_names == ("spin", "slide", "elbow")
    t = np.linspace(0, 10, 200)
    q = np.stack([40 * np.sin(t), 30 * (1 + np.sin(t)), 1.5 * np.sin(t)], axis=1)  # turns, and a slide in cm
    with caplog.at_level(logging.WARNING, logger="diegocal"):
        check_angles(mixed, q)
    assert not caplog.records
    with pytest.raises(LogFormatError, match="joint 'elbow'.*degrees\\? the log wants rad"):
        check_angles(mixed, np.column_stack([q[:, :2], np.degrees(q[:, 2])]))


def test_a_small_excursion_or_one_degrees_do_not_explain_is_a_warning(mixed, caplog):
    t = np.linspace(0, 10, 200)
    base = np.column_stack([np.zeros_like(t), np.full_like(t, 0.1), 2.05 * np.sin(t)])  # 0.05 rad past
    far = base.copy()
    far[:, 2] = -400 * np.sin(t) ** 2  # a joint let turn 60 times past its stop (-7 rad in degrees, not them)
    for q in (base, far):
        caplog.clear()
        with caplog.at_level(logging.WARNING, logger="diegocal"):
            check_angles(mixed, q)
        (record,) = caplog.records
        assert "q past the URDF limits of robot 'mixed'" in record.getMessage() and "elbow" in record.getMessage()
    check_angles(mixed, base, warn=False)  # DynamicsModel.fit_arrays: its callers warned


@pytest.mark.parametrize("name", ["real/tx40.h5", "real/tiago.h5", "arm3_dynamics.h5", "arm3_hidden_friction.h5"])
def test_real_and_sample_logs_pass_without_a_warning(name, caplog):
    log = load_log(SAMPLE / name)
    with caplog.at_level(logging.WARNING, logger="diegocal.sgp"):
        log_arrays(log, robot_for_log(None, log), need_tau=False, warn=False)
    assert not caplog.records


def _scaled_tau(log, factor):
    s = log.streams["tau"]
    return log.with_streams(tau=make_stream(s.names, s.data * factor))


@pytest.mark.parametrize("factor, unit", [(1000.0, "mN·m"), (0.001, "kN·m")])
def test_torques_in_another_unit_are_one_error_line(arm2, arm2_dir, simulate, tmp_path, factor, unit):
    # a user trial: torques in mN·m gave a 'converged' UR5 whose shoulder mc_z was 4432 kg·m
    good, _ = simulate(arm2, T=120, seed=7)
    path = tmp_path / "scaled.h5"
    save_log(_scaled_tau(good, factor), path)
    for args in (["sgp-fit", str(path), "-m", "pr"], ["diagnose", str(path), "--domain", "dynamics"]):
        out = tmp_path / "out"
        res = runner.invoke(app, args + ["--robot", str(arm2_dir), "-o", str(out)])
        assert res.exit_code == 1 and "Traceback" not in res.output, res.output
        line = res.output.strip().splitlines()[-1]
        assert "times what the URDF of robot 'arm2' needs" in line and f"{unit}? the log wants N·m" in line
        assert not out.exists()


@pytest.mark.parametrize("name", ["real/tx40.h5", "real/tiago.h5", "arm3_dynamics.h5", "arm3_hidden_friction.h5"])
def test_real_and_sample_torques_are_far_inside_the_bound(name):
    from diegocal.sgp.streams import TORQUE_FACTOR, check_torque_scale, torque_array

    log = load_log(SAMPLE / name)
    robot = robot_for_log(None, log)
    q, qd, qdd = log_arrays(log, robot, need_tau=False, warn=False)
    tau, joints = torque_array(log, robot, warn=False)
    check_torque_scale(robot, q, qd, qdd, tau, joints)  # no error
    with pytest.raises(LogFormatError, match="mN·m"):
        check_torque_scale(robot, q, qd, qdd, 1000 * tau, joints)
    with pytest.raises(LogFormatError, match="kN·m"):
        check_torque_scale(robot, q, qd, qdd, tau / 1000, joints)
    assert TORQUE_FACTOR < 1000



def test_a_joint_that_never_moves_has_no_friction_written(arm2, arm2_dir, tmp_path):
    # a user trial: a still joint's friction was written 0.0 ± 2.207 (the prior's σ_w, not an estimate)
    from diegocal.sgp.store import load_summary, parameters_of
    from tests.sgp.conftest import excitation, make_log, true_torque

    rng = np.random.default_rng(8)
    t, q, qd, qdd = excitation(arm2, 300, 50.0, rng)
    q[:, 1], qd[:, 1], qdd[:, 1] = 0.3, 0.0, 0.0  # the elbow held still
    tau = true_torque(arm2, q, qd, qdd) + 0.05 * rng.standard_normal(q.shape)
    still = tmp_path / "still.h5"
    save_log(make_log(arm2, q, qd, qdd, tau, t), still)
    out = tmp_path / "still.sgp"
    res = runner.invoke(app, ["sgp-fit", str(still), "--robot", str(arm2_dir), "-m", "pr", "-o", str(out), "-q"])
    assert res.exit_code == 0, res.output
    assert "the log does not identify 2 base parameter(s), written null" in res.output
    params = parameters_of(load_summary(out))
    elbow = [v for k, v in params.items() if k.startswith(("viscous_friction:elbow", "coulomb_friction:elbow"))]
    assert len(elbow) == 2 and all(v["value"] is None and v["stderr"] is None for v in elbow)
    assert all(v["value"] is not None for k, v in params.items() if "friction:shoulder" in k)


@pytest.mark.parametrize("T, held", [(300, False), (12, True)])
def test_a_short_log_says_the_prior_holds_its_parameters(arm2, arm2_dir, simulate, tmp_path, T, held):
    # a user trial: 0.3 s of a UR5 fitted 'converged', its shoulder mc_z pulled to 1.13 against 4.43
    log, _ = simulate(arm2, T=T, seed=3)
    path = tmp_path / "log.h5"
    save_log(log, path)
    res = runner.invoke(app, ["sgp-fit", str(path), "--robot", str(arm2_dir), "-m", "pr", "-o", str(tmp_path / "m")])
    assert res.exit_code == 0, res.output
    assert ("held by the prior more than by the data" in res.output) == held
    assert "does not identify" not in res.output


def test_a_urdf_with_placeholder_inertias_gives_no_torque_scale(arm2, simulate, tmp_path):
    # a review: links of 1 g (a URDF's placeholders) made a log in N·m look 1630 times too large
    import re

    from diegocal.sgp.streams import check_torque_scale, torque_array
    from tests.sgp.conftest import ARM2_URDF

    light = load_robot(write_robot(tmp_path, re.sub(r'mass value="[^"]+"', 'mass value="0.001"', ARM2_URDF)))
    log, _ = simulate(arm2, T=120, seed=7)
    q, qd, qdd = log_arrays(log, light, need_tau=False, warn=False)
    tau, joints = torque_array(log, light, warn=False)
    check_torque_scale(light, q, qd, qdd, tau, joints)  # no scale: no error
    with pytest.raises(LogFormatError, match="mN·m"):
        check_torque_scale(arm2, q, qd, qdd, 1000 * tau, joints)
