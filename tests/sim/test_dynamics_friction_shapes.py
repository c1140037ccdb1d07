"""The dynamics simulator's Stribeck and load frictions (issue #31, item 5): each adds its formula on
its joint only, ``/truth`` records it, the smooth dynamics leave them out with the Coulomb terms,
and appending them to the effects changed no existing effect's log."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from typer.testing import CliRunner

from diegocal.cli import app
from diegocal.io import load_log, save_log
from diegocal.robot import load_robot
from diegocal.robot.model import BUNDLED_ROBOTS
from diegocal.sim.dynamics import DynamicsOptions, build_true_dynamics, simulate_dynamics, true_friction

runner = CliRunner()


@pytest.fixture(scope="module")
def arm3():
    return load_robot(BUNDLED_ROBOTS / "arm3")


def _sim(robot, effects=(), seed=4, **kw):
    kw = {"duration": 4.0, "noise": 0.0, **kw}
    opts = DynamicsOptions(effects=tuple(effects), **kw)
    return simulate_dynamics(robot, opts, np.random.default_rng(seed))


def _diff(robot, effect, others=(), seed=4):
    """The log with ``effect`` (and ``others``), and its measured torque less the one without it."""
    a, b = _sim(robot, (effect, *others), seed), _sim(robot, others, seed)
    np.testing.assert_array_equal(a.streams["q"].data, b.streams["q"].data)
    return a, b, a.streams["tau"].data - b.streams["tau"].data


def test_a_stribeck_friction_is_its_peak_above_coulomb_on_its_joint(arm3):
    log, _, d = _diff(arm3, "stribeck_friction:joint2=0.3")
    rec = log.truth.effects[0]
    assert (rec["cause"], rec["channel"], rec["region"]) == ("stribeck_friction", "joint2", None)
    assert rec["values"] == {"amplitude": 0.3, "velocity_scale": 0.05}
    qd = log.streams["qd"].data[:, 1]
    np.testing.assert_allclose(d[:, 1], 0.3 * np.sign(qd) * np.exp(-np.abs(qd) / 0.05), atol=1e-12)
    slow = np.abs(qd) < 0.01  # near zero velocity the peak is nearly all of it
    assert slow.any() and (np.abs(d[slow, 1]) > 0.24).all()
    np.testing.assert_array_equal(d[:, [0, 2]], 0.0)


def test_a_load_friction_grows_with_the_torque_the_true_links_apply(arm3):
    """With a payload and an armature on its joint: c·|τ_rb|·sign(qd), τ_rb the log without it less
    its friction and the rotor's torque (the payload's inertia in it, the armature's not)."""
    others = ("payload:link3=0.4", "armature:joint2=0.05")
    log, base, d = _diff(arm3, "load_friction:joint2=0.08", others)
    rec = next(r for r in log.truth.effects if r["cause"] == "load_friction")
    assert (rec["channel"], rec["values"]) == ("joint2", {"coefficient": 0.08})
    q, qd, qdd = (log.streams[k].data for k in ("q", "qd", "qdd"))
    f = true_friction(log.truth.params)
    inertia = next(r for r in log.truth.effects if r["cause"] == "armature")["values"]["inertia"]
    rb = base.streams["tau"].data[:, 1] - f["viscous"]["joint2"] * qd[:, 1] - f["coulomb"]["joint2"] * np.sign(qd[:, 1])
    rb -= inertia * qdd[:, 1]
    np.testing.assert_allclose(d[:, 1], 0.08 * np.abs(rb) * np.sign(qd[:, 1]), atol=1e-10)
    np.testing.assert_array_equal(d[:, [0, 2]], 0.0)
    # not the URDF's rigid body: the payload's weight is in the load
    data = arm3.model.createData()
    urdf = np.array([pin.rnea(arm3.model, data, *x)[1] for x in zip(q, qd, qdd, strict=True)])
    assert np.abs(d[:, 1] - 0.08 * np.abs(urdf) * np.sign(qd[:, 1])).max() > 0.01


def test_defaults_are_scaled_to_the_robot_and_recorded_in_the_file(arm3, tmp_path):
    log = _sim(arm3, ("stribeck_friction:joint3", "load_friction:joint1"))
    save_log(log, tmp_path / "x.h5")
    back = load_log(tmp_path / "x.h5").truth.effects
    assert back == log.truth.effects
    v = {r["cause"]: r["values"] for r in back}
    assert v["load_friction"] == {"coefficient": 0.05}
    assert v["stribeck_friction"]["velocity_scale"] == 0.05 and 0.01 < v["stribeck_friction"]["amplitude"] < 1.0


def test_the_smooth_dynamics_leave_them_out_with_the_coulomb_terms(arm3):
    opts = DynamicsOptions(effects=("stribeck_friction:joint2", "load_friction:joint3"))
    dyn = build_true_dynamics(arm3, opts, np.random.default_rng(0))
    q, qd = np.zeros((1, 3)), np.full((1, 3), 0.01)
    np.testing.assert_allclose(dyn.extra_torque(q, qd, smooth=True), dyn.viscous * qd, atol=1e-15)
    with pytest.raises(ValueError, match="load_friction needs"):
        dyn.extra_torque(q, qd)


def test_a_stribeck_friction_rolls_out_and_a_load_friction_is_refused_there(tmp_path):
    wheel = load_robot(BUNDLED_ROBOTS / "reaction_wheel")
    log = _sim(wheel, ("stribeck_friction:wheel",), trajectory="pole-down", duration=2.0)
    assert log.truth.effects[0]["cause"] == "stribeck_friction"
    res = runner.invoke(app, ["simulate", "dynamics", "--robot", "reaction_wheel", "--trajectory", "pole-down",
                              "--effect", "load_friction", "-o", str(tmp_path / "x.h5")])
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert res.exit_code != 0 and len(lines) == 1 and "load_friction is simulated on prescribed" in lines[0]
    assert not (tmp_path / "x.h5").exists()


@pytest.mark.parametrize(
    "effects",
    [("position_friction:joint2",), ("coupled_friction", "torque_gain"), ("torque_offset", "payload", "spring")],
)
def test_an_existing_effects_log_is_the_same_with_the_new_ones_known(arm3, effects):
    """The new effects draw nothing from the effects' generator: a log of the same seed with one of
    them added on another joint has the others' records and torques unchanged (but for its own)."""
    a = _sim(arm3, effects, seed=3)
    b = _sim(arm3, (*effects, "stribeck_friction:joint1=0.2"), seed=3)
    assert b.truth.effects[: len(effects)] == a.truth.effects
    d = b.streams["tau"].data - a.streams["tau"].data
    np.testing.assert_array_equal(d[:, 1:], 0.0)
