"""Dynamics simulator: torques equal rnea + friction + effects exactly, effects act only where they
should, integrated roll-outs are consistent, and bad input gives one clear line."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest
from typer.testing import CliRunner

from diegocal.cli import app
from diegocal.io import load_log
from diegocal.robot import load_robot
from diegocal.robot.model import BUNDLED_ROBOTS
from diegocal.sim.dynamics import DynamicsOptions, simulate_dynamics, true_friction, true_inertial

runner = CliRunner()


@pytest.fixture(scope="module")
def arm3():
    return load_robot(BUNDLED_ROBOTS / "arm3")


@pytest.fixture(scope="module")
def wheel():
    return load_robot(BUNDLED_ROBOTS / "reaction_wheel")


def _sim(robot, seed=0, **kw):
    kw.setdefault("duration", 4.0)
    kw.setdefault("noise", 0.0)
    return simulate_dynamics(robot, DynamicsOptions(**kw), np.random.default_rng(seed))


def _signals(log):
    return tuple(log.streams[k].data for k in ("q", "qd", "qdd", "tau"))


def _rnea(robot, q, qd, qdd):
    data = robot.model.createData()
    return np.array([pin.rnea(robot.model, data, *x) for x in zip(q, qd, qdd, strict=True)])


def test_tau_is_rnea_plus_friction_exactly(arm3):
    log = _sim(arm3, trajectory="excitation")
    q, qd, qdd, tau = _signals(log)
    p = true_friction(log.truth.params)
    visc = np.array([p["viscous"][j] for j in arm3.joint_names])
    coul = np.array([p["coulomb"][j] for j in arm3.joint_names])
    assert (visc > 0).all() and (coul > 0).all()
    want = _rnea(arm3, q, qd, qdd) + visc * qd + coul * np.sign(qd)
    np.testing.assert_allclose(tau, want, rtol=0, atol=1e-10)
    assert (q >= arm3.lower).all() and (q <= arm3.upper).all()


def test_noise_is_seeded_and_has_the_requested_level(arm3):
    a = _sim(arm3, seed=3, noise=0.05, duration=10.0)
    b = _sim(arm3, seed=3, noise=0.05, duration=10.0)
    np.testing.assert_array_equal(a.streams["tau"].data, b.streams["tau"].data)
    resid = a.streams["tau"].data - a.truth.signals["tau"].data
    assert 0.045 < resid.std() < 0.055
    c = _sim(arm3, seed=4, noise=0.05, duration=10.0)
    assert not np.allclose(a.streams["q"].data, c.streams["q"].data)


@pytest.mark.parametrize(
    "effect, check",
    [
        ("viscous_friction:joint2", lambda v, q, qd: v["viscous"] * qd),
        ("coulomb_friction:joint2", lambda v, q, qd: v["coulomb"] * np.sign(qd)),
        ("spring:joint2", lambda v, q, qd: v["stiffness"] * (q - v["rest"])),
        ("torque_offset:joint2", lambda v, q, qd: np.full_like(q, v["offset"])),
    ],
)
def test_each_joint_effect_adds_its_term_on_its_joint_only(arm3, effect, check):
    base = _sim(arm3, seed=5)
    log = _sim(arm3, seed=5, effects=(effect,))
    np.testing.assert_array_equal(base.streams["q"].data, log.streams["q"].data)
    diff = log.streams["tau"].data - base.streams["tau"].data
    (rec,) = log.truth.effects
    assert rec["cause"] == effect.split(":")[0] and rec["channel"] == "joint2"
    q, qd = log.streams["q"].data[:, 1], log.streams["qd"].data[:, 1]
    np.testing.assert_allclose(diff[:, 1], check(rec["values"], q, qd), atol=1e-10)
    assert np.abs(diff[:, 1]).max() > 1e-3
    np.testing.assert_allclose(diff[:, [0, 2]], 0.0, atol=1e-12)


def test_position_friction_acts_only_inside_its_region(arm3):
    opts = dict(seed=6, duration=8.0, regions={"joint3": (1.0, 1.6)})
    base = _sim(arm3, **opts)
    log = _sim(arm3, effects=("position_friction:joint3",), **opts)
    diff = log.streams["tau"].data - base.streams["tau"].data
    q3 = log.streams["q"].data[:, 2]
    (rec,) = log.truth.effects
    assert rec["region"] == {"variable": "q.joint3", "low": 1.0, "high": 1.6}
    inside = (q3 >= 1.0) & (q3 <= 1.6)
    assert 0.1 < inside.mean() < 0.9
    np.testing.assert_array_equal(diff[~inside], 0.0)
    assert (np.abs(diff[inside, 2]) > 0).mean() > 0.95
    np.testing.assert_array_equal(diff[:, :2], 0.0)


def test_pendulum_default_region_is_the_thesis_interval():
    log = _sim(load_robot(BUNDLED_ROBOTS / "pendulum"), effects=("position_friction",))
    (rec,) = log.truth.effects
    assert (rec["region"]["low"], rec["region"]["high"]) == (2.0, 2.5)


def test_payload_changes_rigid_body_torque_like_a_point_mass(arm3):
    base = _sim(arm3, seed=7)
    log = _sim(arm3, seed=7, effects=("payload:link3",))
    (rec,) = log.truth.effects
    v = rec["values"]
    model = arm3.model.copy()
    jid = model.frames[[f.name for f in model.frames].index("link3")].parentJoint
    model.inertias[jid] += pin.Inertia(v["mass"], np.array([v["x"], v["y"], v["z"]]), np.zeros((3, 3)))
    data = model.createData()
    q, qd, qdd, tau = _signals(log)
    rb_new = np.array([pin.rnea(model, data, *x) for x in zip(q, qd, qdd, strict=True)])
    diff = tau - base.streams["tau"].data
    np.testing.assert_allclose(diff, rb_new - _rnea(arm3, q, qd, qdd), atol=1e-10)
    assert np.abs(diff[:, 1]).max() > 0.05
    assert true_inertial(log.truth.params)["joint3"][0] == pytest.approx(0.8 + v["mass"])


@pytest.mark.parametrize("trajectory", ["pole-down", "pole-up"])
def test_rollouts_are_consistent_with_inverse_dynamics(wheel, trajectory):
    log = _sim(wheel, trajectory=trajectory, duration=5.0)
    q, qd, qdd, tau = _signals(log)
    p = true_friction(log.truth.params)
    visc = np.array([p["viscous"][j] for j in wheel.joint_names])
    coul = np.array([p["coulomb"][j] for j in wheel.joint_names])
    np.testing.assert_allclose(tau, _rnea(wheel, q, qd, qdd) + visc * qd + coul * np.sign(qd), atol=1e-9)
    # the integration is right: q is the integral of qd (trapezoid at 100 Hz, small error) and
    # qd that of qdd (the LQR loop is fast for 100 Hz: a loose check, catches sign or scale slips)
    dt = 0.01
    for x, xd, tol in ((q, qd, 0.02), (qd, qdd, 0.5)):
        err = np.diff(x, axis=0) - dt * 0.5 * (xd[1:] + xd[:-1])
        rel = np.sqrt((err**2).mean(0) / (np.diff(x, axis=0) ** 2).mean(0))
        assert (rel < tol).all(), rel
    if trajectory == "pole-up":
        assert np.abs(q[:, 0] - np.pi).max() < 0.3  # balanced about the upright
        assert q[:, 0].std() > 1e-3  # wanders (disturbance), not static
    else:
        assert np.abs(q[:, 0]).max() < 1.5 and q[:, 0].std() > 0.05


def test_figure_eights_are_different_planes(arm3):
    h = _sim(arm3, trajectory="figure8-horizontal", duration=4.0, rate_hz=50.0)
    v = _sim(arm3, trajectory="figure8-vertical", duration=4.0, rate_hz=50.0)
    model, data = arm3.model, arm3.model.createData()
    fid = model.getFrameId("tool")

    def tool(q):
        out = []
        for x in q:
            pin.framesForwardKinematics(model, data, x)
            out.append(data.oMf[fid].translation.copy())
        return np.array(out)

    ph, pv = tool(h.streams["q"].data), tool(v.streams["q"].data)
    assert np.ptp(ph[:, 2]) < 1e-6 and np.ptp(ph[:, 1]) > 0.05
    assert np.ptp(pv[:, 1]) < 1e-6 and np.ptp(pv[:, 2]) > 0.05
    # qd is the derivative of q
    qh = h.streams["q"].data
    np.testing.assert_allclose(np.gradient(qh, 0.02, axis=0)[1:-1], h.streams["qd"].data[1:-1], atol=0.02)


def test_options_are_validated(arm3):
    from diegocal.errors import DiegocalError

    with pytest.raises(DiegocalError, match="viscous"):
        _sim(arm3, viscous=(1.0, 2.0))
    with pytest.raises(DiegocalError, match="low must be < high"):
        _sim(arm3, effects=("position_friction:joint3",), regions={"joint3": (2.0, 1.0)})
    with pytest.raises(DiegocalError, match="not a dynamics effect"):
        _sim(arm3, effects=("backlash:joint1",))


def test_cli_end_to_end(tmp_path):
    out = tmp_path / "arm.h5"
    args = [
        "simulate",
        "dynamics",
        "--robot",
        "arm3",
        "-o",
        str(out),
        "--duration",
        "2",
        "--effect",
        "position_friction:joint3",
        "--region",
        "joint3:1.0:1.5",
        "--seed",
        "2",
    ]
    res = runner.invoke(app, args)
    assert res.exit_code == 0, res.output
    log = load_log(out)
    assert set(log.streams) == {"q", "qd", "qdd", "tau"} and log.robot == "arm3"
    assert log.truth.effects[0]["region"]["low"] == 1.0
    again = tmp_path / "again.h5"
    runner.invoke(app, args[:5] + [str(again)] + args[6:])
    np.testing.assert_array_equal(load_log(again).streams["tau"].data, log.streams["tau"].data)


def test_robot_seed_records_another_sessions_robot(tmp_path):
    """--robot-seed S: the friction and the effects of the session of --seed S (a held-out log of
    the same robot), with this session's own trajectory and noise."""
    base = ["simulate", "dynamics", "--robot", "arm3", "--duration", "2", "--effect", "armature", "-q"]
    runs = {"a.h5": ["--seed", "1"], "b.h5": ["--seed", "2", "--robot-seed", "1"], "c.h5": ["--seed", "2"]}
    for name, extra in runs.items():
        res = runner.invoke(app, base + ["-o", str(tmp_path / name)] + extra)
        assert res.exit_code == 0, res.output
    a, b, c = (load_log(tmp_path / n) for n in ("a.h5", "b.h5", "c.h5"))
    fa, fb, fc = (true_friction(x.truth.params) for x in (a, b, c))
    for key in ("viscous", "coulomb"):
        assert fb[key] == fa[key]
        assert fc[key] != fa[key]  # a seed of its own draws another robot
    assert b.truth.effects == a.truth.effects
    assert not np.allclose(b.streams["q"].data, a.streams["q"].data)  # its own trajectory
    np.testing.assert_array_equal(b.streams["q"].data, c.streams["q"].data)


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--effect", "position_friction:elbow"], "'elbow' is not a joint"),
        (["--effect", "backlash"], "not a dynamics effect"),
        (["--trajectory", "circle"], "unknown trajectory 'circle'"),
        (["--duration", "-1"], "duration must be a positive"),
        (["--noise", "-0.1"], "noise must be a non-negative"),
        (["--region", "joint3:a:b"], "expected JOINT:LOW:HIGH"),
        (["--region", "elbow:1:2"], "no joint 'elbow'"),
        (["--robot", "no_such_robot"], "not found"),
    ],
)
def test_cli_bad_input_one_line(tmp_path, extra, message):
    args = [
        "simulate",
        "dynamics",
        "--robot",
        "arm3",
        "-o",
        str(tmp_path / "x.h5"),
        "--duration",
        "1",
    ]
    res = runner.invoke(app, args + extra)
    assert res.exit_code != 0
    assert message in res.output
    assert "Traceback" not in res.output
    assert not (tmp_path / "x.h5").exists()


def test_pole_up_needs_two_joints(tmp_path):
    res = runner.invoke(
        app,
        [
            "simulate",
            "dynamics",
            "--robot",
            "pendulum",
            "--trajectory",
            "pole-up",
            "-o",
            str(tmp_path / "p.h5"),
        ],
    )
    assert res.exit_code != 0 and "needs a passive pole joint" in res.output


def test_replace_keeps_options_frozen():
    opts = DynamicsOptions()
    assert replace(opts, noise=0.0).noise == 0.0 and opts.noise == 0.01


def test_whirl_turns_one_way_and_wraps_into_the_limits():
    robot = load_robot(BUNDLED_ROBOTS / "pendulum")
    opts = dict(trajectory="whirl", duration=10.0, viscous=0.0, coulomb=0.0)
    log = _sim(robot, effects=("position_friction",), **opts)
    q, qd, qdd, tau = _signals(log)
    assert (qd > 0).all()
    assert (q >= robot.lower).all() and (q < robot.lower + 2 * np.pi).all()
    assert np.histogram(q, bins=6, range=(-np.pi, np.pi))[0].min() > 0.1 * len(q) / 6
    # one direction only: inside the region the friction is a constant (Coulomb) + viscous push
    (rec,) = log.truth.effects
    v, inside = rec["values"], (q[:, 0] >= 2.0) & (q[:, 0] <= 2.5)
    extra = tau[:, 0] - _rnea(robot, q, qd, qdd)[:, 0]
    np.testing.assert_allclose(extra[inside], v["coulomb"] + v["viscous"] * qd[inside, 0], atol=1e-10)
    np.testing.assert_allclose(extra[~inside], 0.0, atol=1e-10)


def test_figure_eight_scales_to_a_small_robot():
    finger = load_robot(BUNDLED_ROBOTS / "finger")
    log = _sim(finger, trajectory="figure8-vertical", duration=2.0, rate_hz=50.0)
    q = log.streams["q"].data
    assert (q >= finger.lower).all() and (q <= finger.upper).all() and np.ptp(q, axis=0).max() > 0.05


# ----------------------------------------------------------------------------- effects of issue #13
def _diff(robot, effect, seed=4):
    """Measured torque with ``effect`` minus without (same friction and trajectory), no noise."""
    a = _sim(robot, seed=seed, effects=(effect,))
    b = _sim(robot, seed=seed)
    np.testing.assert_array_equal(a.streams["q"].data, b.streams["q"].data)
    return a, a.streams["tau"].data - b.streams["tau"].data


def test_armature_is_a_rotor_inertia_on_its_joint(arm3):
    log, d = _diff(arm3, "armature:joint3=0.05")
    inertia = log.truth.effects[0]["values"]["inertia"]
    qdd = log.streams["qdd"].data
    np.testing.assert_allclose(d[:, 2], inertia * qdd[:, 2], atol=1e-9)
    assert np.abs(d[:, :2]).max() < 1e-9


def test_coupled_friction_acts_on_the_joint_and_the_one_before(arm3):
    log, d = _diff(arm3, "coupled_friction:joint3=0.05")
    rec = log.truth.effects[0]
    v = rec["values"]
    assert rec["partner"] == "joint2" and v["ratio"] == 1.0 and v["coulomb"] == 0.05
    qd = log.streams["qd"].data
    motor = qd[:, 2] + qd[:, 1]
    want = v["coulomb"] * np.tanh(motor / 0.05) + v["viscous"] * motor
    np.testing.assert_allclose(d[:, 2], want, atol=1e-9)
    np.testing.assert_allclose(d[:, 1], want, atol=1e-9)
    assert np.abs(d[:, 0]).max() < 1e-9


def test_torque_lag_is_a_first_order_sensor_on_its_joint(arm3):
    from diegocal.sgp.terms import lag_filter

    a = _sim(arm3, seed=4, effects=("torque_lag:joint1=0.02",))
    b = _sim(arm3, seed=4)
    assert a.truth.effects[0]["values"]["lag"] == 0.02
    tau_a, tau_b = a.streams["tau"].data, b.streams["tau"].data
    np.testing.assert_allclose(tau_a[:, 0], lag_filter(tau_b[:, 0], b.time, 0.02), atol=1e-9)
    np.testing.assert_array_equal(tau_a[:, 1:], tau_b[:, 1:])
    assert np.abs(tau_a[:, 0] - tau_b[:, 0]).max() > 1e-3


@pytest.mark.parametrize(
    "effect,key,want",
    [
        ("torque_offset:joint2=0.07", "offset", 0.07),
        ("coulomb_friction:joint1=0.2", "coulomb", 0.2),
        ("payload=0.3", "mass", 0.3),
    ],
)
def test_effect_sizes_are_honoured(arm3, effect, key, want):
    log = _sim(arm3, seed=2, effects=(effect,))
    assert abs(log.truth.effects[0]["values"][key]) == pytest.approx(want)
