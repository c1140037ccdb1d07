"""The kinematics simulator against its own observation models and its injected truth."""

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from diegocal.cli import app
from diegocal.io import load_log, save_log
from diegocal.robot import load_robot, pot_transmission, predict_markers
from diegocal.sim import (
    EffectError,
    KinematicsOptions,
    SimOptionError,
    parse_effects,
    simulate_kinematics,
)
from diegocal.sim.kinematics import backlash, occlusion_mask
from diegocal.stac.calibration import Calibration

TINY = Path(__file__).parent / "fixtures" / "kin_tiny"
ROBOTS = Path(__file__).resolve().parents[2] / "robots"


@pytest.fixture(scope="module")
def robot():
    return load_robot(TINY)


def simulate(robot, seed=7, **kw):
    kw.setdefault("duration", 30.0)
    if "effects" in kw:
        kw["effects"] = parse_effects(kw["effects"])
    return simulate_kinematics(robot, KinematicsOptions(**kw), np.random.default_rng(seed))


@pytest.fixture(scope="module")
def base(robot):
    return simulate(robot)


# ----------------------------------------------------------------------------- the model
def test_pots_follow_true_gain_and_bias_within_noise(robot, base):
    truth = Calibration.from_dict(base.truth.params)
    q = base.truth.signals["q"].data
    resid = base.streams["pots"].data - (truth.gain * pot_transmission(robot, q) + truth.bias)
    assert abs(resid.mean()) < 5 * 0.005 / np.sqrt(resid.size)  # 5 standard errors
    np.testing.assert_allclose(resid.std(axis=0), 0.005, rtol=0.1)


def test_markers_follow_true_frame_and_positions_within_noise(robot, base):
    truth = Calibration.from_dict(base.truth.params)
    q = base.truth.signals["q"].data
    pred = predict_markers(robot, q, truth.marker_xyz, truth.mocap_R, truth.mocap_T)
    x = base.streams["markers"].data
    seen = np.isfinite(x[..., 0])
    resid = (x - pred)[seen]
    np.testing.assert_allclose(resid.std(axis=0), 0.002, rtol=0.1)
    assert np.abs(resid.mean(axis=0)).max() < 2e-4


def test_truth_is_drawn_around_the_nominal_values(robot, base):
    truth, nominal = Calibration.from_dict(base.truth.params), Calibration.nominal(robot)
    ratio = truth.gain / nominal.gain
    assert np.all(np.abs(ratio - 1) <= 0.2) and np.any(np.abs(ratio - 1) > 0.02)
    assert truth.gain[robot.sensors.pot_names.index("slide")] == 1.0  # encoder gain stays 1
    dist = np.linalg.norm(truth.marker_xyz - nominal.marker_xyz, axis=1)
    assert np.all((dist >= 0.015 - 1e-12) & (dist <= 0.045 + 1e-12))
    np.testing.assert_allclose(truth.mocap_R @ truth.mocap_R.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(truth.mocap_R) == pytest.approx(1.0)
    assert base.truth.params["sigma"] == {"pots": 0.005, "markers": 0.002}


def test_joints_move_over_their_range_within_limits(robot, base):
    q = base.truth.signals["q"].data
    assert np.all(q >= robot.lower - 1e-12) and np.all(q <= robot.upper + 1e-12)
    covered = (q.max(0) - q.min(0)) / (robot.upper - robot.lower)
    assert covered.min() > 0.4
    qd = base.truth.signals["qd"].data
    agree = np.abs(np.gradient(q, 0.01, axis=0) - qd) < 0.1  # apart from hard stops at limits
    assert agree.mean() > 0.99


def test_same_seed_same_file_other_seed_other_data(robot, base, tmp_path):
    a, b = tmp_path / "a.h5", tmp_path / "b.h5"
    save_log(base, a)
    save_log(simulate(robot), b)
    assert a.read_bytes() == b.read_bytes()
    other = simulate(robot, seed=8)
    assert not np.allclose(other.streams["pots"].data, base.streams["pots"].data)
    back = load_log(a)
    assert back.truth.params == base.truth.params
    np.testing.assert_array_equal(back.streams["markers"].data, base.streams["markers"].data)


def test_robot_seed_records_that_sessions_robot_with_its_own_motion(robot, base):
    """--robot-seed: the calibration, mocap frame and effects of the seed's session; the motion
    and noise of this one (held-out sessions of one robot); its own seed gives its own log."""
    effects = ["sensor_nonlinearity", "marker_slip"]
    own = simulate(robot, seed=7, effects=effects)
    same = simulate(robot, seed=7, effects=effects, robot_seed=7)
    np.testing.assert_array_equal(same.streams["pots"].data, own.streams["pots"].data)
    other = simulate(robot, seed=8, effects=effects, robot_seed=7)
    assert other.truth.params == own.truth.params
    assert other.truth.effects == own.truth.effects
    assert not np.allclose(other.truth.signals["q"].data, own.truth.signals["q"].data)
    assert simulate(robot, seed=8, effects=effects).truth.params != own.truth.params


# ----------------------------------------------------------------------------- occlusion
def test_occlusion_runs_hit_the_target_fraction():
    mask = occlusion_mask(200_000, 8, 0.1, 50.0, np.random.default_rng(0))
    # renewal theory: sd of one marker's fraction ~ 0.0064 here (400 occlusion cycles)
    np.testing.assert_allclose(mask.mean(axis=0), 0.1, atol=0.03)
    assert mask.mean() == pytest.approx(0.1, abs=0.01)
    starts = (mask[1:] & ~mask[:-1]).sum(axis=0)
    mean_run = mask.sum(axis=0) / np.maximum(starts, 1)
    np.testing.assert_allclose(mean_run, 50.0, rtol=0.15)
    assert not occlusion_mask(1000, 3, 0.0, 50.0, np.random.default_rng(0)).any()


def test_log_markers_are_occluded_in_runs(base):
    nan = np.isnan(base.streams["markers"].data)
    assert (nan.all(axis=2) == nan.any(axis=2)).all()  # a marker is occluded on all axes at once
    occ = nan[..., 0]
    assert 0.03 < occ.mean() < 0.2
    runs = (occ[1:] & ~occ[:-1]).sum() + occ[0].sum()
    assert occ.sum() / runs > 20  # mean run 0.5 s = 50 samples, not isolated samples


# ----------------------------------------------------------------------------- effects
def _noise_free(**kw):
    return dict(pot_noise=0.0, marker_noise=0.0, occlusion=0.0, **kw)


@pytest.fixture(scope="module")
def clean(robot):
    return simulate(robot, **_noise_free())


def _effect(log):
    (record,) = log.truth.effects
    return record


def test_link_offset_moves_only_the_markers_below_that_joint(robot, clean):
    log = simulate(robot, **_noise_free(effects=["link_offset:shoulder"]))
    d = np.array(_effect(log)["values"]["dxyz"])
    assert 0.005 <= np.linalg.norm(d) <= 0.010
    np.testing.assert_array_equal(log.streams["pots"].data, clean.streams["pots"].data)
    shift = log.streams["markers"].data - clean.streams["markers"].data
    names = robot.sensors.marker_names
    for m in ("m_upper", "m_lower", "m_slider"):  # on the shoulder's subtree: shifted by |d|
        np.testing.assert_allclose(np.linalg.norm(shift[:, names.index(m)], axis=1), np.linalg.norm(d), rtol=1e-9)
    for m in ("m_head", "m_finger"):
        np.testing.assert_array_equal(shift[:, names.index(m)], 0.0)
    R = Calibration.from_dict(log.truth.params).mocap_R  # waist is the base: shift = R d
    np.testing.assert_allclose(shift[:, names.index("m_upper")], np.tile(R @ d, (log.n_samples, 1)), atol=1e-12)


def test_link_offset_reaches_linear_pots_through_their_anchors(robot, clean):
    log = simulate(robot, **_noise_free(effects=["link_offset:neck_pitch"]))
    diff = log.streams["pots"].data - clean.streams["pots"].data
    changed = np.array(robot.sensors.pot_names)[np.abs(diff).max(0) > 1e-9]
    assert set(changed) == {"neck_a", "neck_b"}


def test_sensor_nonlinearity_adds_the_recorded_quadratic_to_one_pot(robot, clean):
    log = simulate(robot, **_noise_free(effects=["sensor_nonlinearity:flex"]))
    v = _effect(log)["values"]
    i = robot.sensors.pot_names.index("flex")
    diff = log.streams["pots"].data - clean.streams["pots"].data
    s = pot_transmission(robot, log.truth.signals["q"].data)[:, i]
    np.testing.assert_allclose(diff[:, i], v["c2"] * (s - v["s0"]) ** 2, atol=1e-12)
    assert np.abs(diff[:, i]).max() == pytest.approx(abs(v["peak"]), rel=1e-6)
    np.testing.assert_array_equal(np.delete(diff, i, axis=1), 0.0)
    np.testing.assert_array_equal(log.streams["markers"].data, clean.streams["markers"].data)


def test_backlash_lags_the_reading_in_the_direction_of_motion(robot, clean):
    log = simulate(robot, **_noise_free(effects=["backlash:elbow"]))
    v = _effect(log)["values"]
    i = robot.sensors.pot_names.index("elbow")
    truth = Calibration.from_dict(log.truth.params)
    lag = (log.streams["pots"].data - clean.streams["pots"].data)[:, i] / truth.gain[i]  # rad
    qd = log.truth.signals["qd"].data[:, robot.joint_index("elbow")]
    half = 0.5 * v["width"]
    assert np.abs(lag).max() <= half + 1e-12
    up, down = qd > 0.2, qd < -0.2
    # moving up the reading trails by half the band, moving down it leads; after a reversal it
    # crosses the band, so the lag only ever decreases while moving up (increases moving down)
    assert np.mean(np.isclose(lag[up], -half, atol=1e-9)) > 0.7
    assert np.mean(np.isclose(lag[down], half, atol=1e-9)) > 0.7
    step = np.diff(lag)
    assert (step[up[1:]] <= 1e-12).all() and (step[down[1:]] >= -1e-12).all()
    np.testing.assert_array_equal(np.delete(log.streams["pots"].data - clean.streams["pots"].data, i, axis=1), 0.0)


def test_backlash_operator_is_a_dead_band():
    s = np.array([0.0, 0.01, 0.05, 0.1, 0.08, 0.06, 0.0])
    np.testing.assert_allclose(backlash(s, 0.04), [0.0, 0.0, 0.03, 0.08, 0.08, 0.08, 0.02])


def test_time_offset_shifts_the_mocap_clock_only(robot, clean):
    log = simulate(robot, **_noise_free(effects=["time_offset:markers"]))
    k = _effect(log)["values"]["samples"]
    assert 3 <= abs(k) <= 8
    np.testing.assert_array_equal(log.streams["pots"].data, clean.streams["pots"].data)
    a, b = log.streams["markers"].data, clean.streams["markers"].data
    lo, hi = max(0, -k), log.n_samples - max(0, k)
    np.testing.assert_allclose(a[lo:hi], b[lo + k : hi + k], atol=1e-12)
    assert np.abs(a - b).max() > 1e-3


def test_marker_slip_moves_one_marker_from_the_recorded_time(robot, clean):
    log = simulate(robot, **_noise_free(effects=["marker_slip:m_lower"]))
    rec = _effect(log)
    t0, d = rec["values"]["sample"], np.array(rec["values"]["dxyz"])
    assert rec["region"]["low"] == pytest.approx(log.time[t0])
    m = robot.sensors.marker_names.index("m_lower")
    diff = log.streams["markers"].data - clean.streams["markers"].data
    np.testing.assert_array_equal(diff[:t0], 0.0)
    np.testing.assert_allclose(np.linalg.norm(diff[t0:, m], axis=1), np.linalg.norm(d), rtol=1e-9)
    np.testing.assert_array_equal(np.delete(diff, m, axis=1), 0.0)
    np.testing.assert_array_equal(log.streams["pots"].data, clean.streams["pots"].data)


def test_marker_outliers_displace_short_runs_of_readings(robot, clean):
    log = simulate(robot, **_noise_free(effects=["marker_outliers"]))
    rec = _effect(log)
    assert rec["channel"] == "markers" and 0.01 <= rec["values"]["fraction"] <= 0.03
    bad = log.truth.signals["markers_corrupted"].data.astype(bool)
    diff = log.streams["markers"].data - clean.streams["markers"].data
    moved = np.linalg.norm(diff, axis=-1)
    np.testing.assert_array_equal(moved > 0, bad)  # only the recorded readings, and all of them
    assert np.all((moved[bad] >= 0.03 - 1e-12) & (moved[bad] <= 0.15 + 1e-12))
    # every marker gets its share, in runs of 1-5 samples
    np.testing.assert_allclose(bad.mean(axis=0), rec["values"]["fraction"], atol=0.005)
    starts = (bad[1:] & ~bad[:-1]).sum(axis=0) + bad[0]
    assert np.all(bad.sum(axis=0) / starts <= 5) and bad.sum() == rec["values"]["samples"]
    np.testing.assert_array_equal(log.streams["pots"].data, clean.streams["pots"].data)


def test_swapped_labels_exchange_two_nearby_markers_in_runs(robot, clean):
    log = simulate(robot, **_noise_free(effects=["swapped_labels:m_lower"]))
    rec = _effect(log)
    names = robot.sensors.marker_names
    m, k = names.index("m_lower"), names.index(rec["values"]["partner"])
    x, x0 = log.streams["markers"].data, clean.streams["markers"].data
    dist = np.linalg.norm(x0 - x0[:, m : m + 1], axis=-1).mean(axis=0)
    assert k == np.argsort(dist)[1]  # the nearest other marker
    bad = log.truth.signals["markers_corrupted"].data.astype(bool)
    swapped = bad[:, m]
    np.testing.assert_array_equal(bad[:, k], swapped)
    assert swapped.sum() == rec["values"]["samples"] and 0.03 <= rec["values"]["fraction"] <= 0.08
    np.testing.assert_array_equal(x[swapped, m], x0[swapped, k])
    np.testing.assert_array_equal(x[swapped, k], x0[swapped, m])
    np.testing.assert_array_equal(x[~bad], x0[~bad])
    starts = (swapped[1:] & ~swapped[:-1]).sum() + swapped[0]
    assert starts == rec["values"]["runs"] and 20 <= swapped.sum() / starts <= 100  # 0.2-1 s at 100 Hz
    assert "markers_corrupted" not in clean.truth.signals


def test_sizes_are_honoured_on_the_channel_they_act_on(robot, clean):
    """``CAUSE:CHANNEL=SIZE`` sets the magnitude in the unit the CLI's help states (SIZE_UNITS)."""
    names = robot.sensors.marker_names
    truth = Calibration.from_dict(clean.truth.params)
    log = simulate(robot, **_noise_free(effects=["link_offset:shoulder=0.013"]))
    assert np.linalg.norm(_effect(log)["values"]["dxyz"]) == pytest.approx(0.013)
    moved = np.linalg.norm(log.streams["markers"].data - clean.streams["markers"].data, axis=-1)
    np.testing.assert_allclose(moved[:, names.index("m_lower")], 0.013, rtol=1e-9)

    i = robot.sensors.pot_names.index("elbow")
    log = simulate(robot, **_noise_free(effects=["sensor_nonlinearity:elbow=0.02"]))
    diff = (log.streams["pots"].data - clean.streams["pots"].data)[:, i]
    assert np.abs(diff).max() == pytest.approx(0.02, rel=1e-6)

    log = simulate(robot, **_noise_free(effects=["backlash:elbow=0.03"]))
    assert _effect(log)["values"]["width_reading"] == pytest.approx(0.03)
    lag = (log.streams["pots"].data - clean.streams["pots"].data)[:, i]
    assert np.abs(lag).max() == pytest.approx(0.015, rel=1e-6)  # half the band, at the true gain
    assert abs(truth.gain[i]) * _effect(log)["values"]["width"] == pytest.approx(0.03)

    log = simulate(robot, **_noise_free(effects=["marker_slip:m_lower=0.004"]))
    d = log.streams["markers"].data - clean.streams["markers"].data
    assert np.linalg.norm(d[:, names.index("m_lower")], axis=-1).max() == pytest.approx(0.004)

    log = simulate(robot, **_noise_free(effects=["marker_outliers=0.007"]))
    bad = log.truth.signals["markers_corrupted"].data.astype(bool)
    moved = np.linalg.norm(log.streams["markers"].data - clean.streams["markers"].data, axis=-1)
    np.testing.assert_allclose(moved[bad], 0.007, rtol=1e-9)

    x0 = clean.streams["markers"].data
    m = names.index("m_lower")
    dist = np.linalg.norm(x0 - x0[:, m : m + 1], axis=-1).mean(axis=0)
    far = int(np.argmax(dist))
    log = simulate(robot, **_noise_free(effects=[f"swapped_labels:m_lower={dist[far]:.6f}"]))
    assert _effect(log)["values"]["partner"] == names[far]
    assert _effect(log)["values"]["distance"] == pytest.approx(dist[far], rel=1e-5)


def test_link_offset_direction_is_honoured(robot):
    log = simulate(robot, **_noise_free(effects=["link_offset:elbow=0.01"], directions={"elbow": (0.0, 0.0, -2.0)}))
    np.testing.assert_allclose(_effect(log)["values"]["dxyz"], [0.0, 0.0, -0.01], atol=1e-15)
    with pytest.raises(SimOptionError, match="no link_offset:shoulder"):
        simulate(robot, effects=["link_offset:elbow"], directions={"shoulder": (1.0, 0.0, 0.0)})
    with pytest.raises(SimOptionError, match="not all 0"):
        simulate(robot, effects=["link_offset:elbow"], directions={"elbow": (0.0, 0.0, 0.0)})


def test_time_offset_size_may_fall_between_samples(robot, clean):
    """A clock shift of 0.125 s at 100 Hz: markers[t] read the clean markers half-way between
    samples t ± 12 and t ± 13 (a smooth path; the run is the clean one: 12.5 samples fit the pad),
    the pots do not move, and /truth says how far the shift moves the markers."""
    log = simulate(robot, **_noise_free(effects=["time_offset:markers=0.125"]))
    v = _effect(log)["values"]
    assert abs(v["seconds"]) == pytest.approx(0.125) and abs(v["samples"]) == pytest.approx(12.5)
    np.testing.assert_array_equal(log.streams["pots"].data, clean.streams["pots"].data)
    a, b = log.streams["markers"].data, clean.streams["markers"].data
    k = 12 if v["seconds"] > 0 else -13
    T = log.n_samples
    mid = 0.5 * (b[max(0, -k) + k : T - max(0, k + 1) + k] + b[max(0, -k) + k + 1 : T - max(0, k + 1) + k + 1])
    got = a[max(0, -k) : T - max(0, k + 1)]
    err = np.abs(got - mid)
    assert np.mean(err < 2e-4) > 0.999 and err.max() < 1e-3  # the curvature over 5 ms (a limit stop: a kink)
    assert np.abs(got - b[max(0, -k) : T - max(0, k + 1)]).max() > 1e-3
    assert v["displacement_rms"] == pytest.approx(np.sqrt(np.mean(np.sum((a - b) ** 2, -1))), rel=1e-9)


def test_bad_sizes_raise_naming_the_effect(robot):
    with pytest.raises(EffectError, match="turn back"):
        simulate(robot, effects=["sensor_nonlinearity:elbow=5"], duration=5.0)
    with pytest.raises(EffectError, match="wider than the pot's range"):
        simulate(robot, effects=["backlash:elbow=50"], duration=5.0)
    with pytest.raises(EffectError, match="half the run"):
        simulate(robot, effects=["time_offset:markers=3"], duration=5.0)
    with pytest.raises(EffectError, match="positive"):
        simulate(robot, effects=["marker_slip:m_lower=-0.01"], duration=5.0)


def test_effects_without_channel_pick_a_valid_one_reproducibly(robot):
    effects = ["backlash", "link_offset", "marker_slip", "swapped_labels", "marker_outliers"]
    a = simulate(robot, effects=effects, duration=5.0)
    b = simulate(robot, effects=effects, duration=5.0)
    assert a.truth.effects == b.truth.effects
    np.testing.assert_array_equal(a.streams["markers"].data, b.streams["markers"].data)
    by = {e["cause"]: e["channel"] for e in a.truth.effects}
    assert by["backlash"] in robot.sensors.pot_names
    assert by["link_offset"] in robot.joint_names
    assert by["marker_slip"] in robot.sensors.marker_names
    assert by["swapped_labels"] in robot.sensors.marker_names and by["marker_outliers"] == "markers"


def test_bad_effects_and_options_raise(robot):
    with pytest.raises(EffectError, match="not a kinematics effect"):
        simulate(robot, effects=["coulomb_friction:elbow"])
    with pytest.raises(KeyError, match="not a joint"):
        simulate(robot, effects=["link_offset:wrist"])
    with pytest.raises(SimOptionError, match="duration"):
        simulate(robot, duration=-1.0)
    with pytest.raises(SimOptionError, match="occlusion"):
        simulate(robot, occlusion=1.0)


# ----------------------------------------------------------------------------- robots
@pytest.mark.parametrize("name", ["finger", "diego"])
def test_bundled_robots_simulate(name):
    if not (ROBOTS / name / "sensors.yaml").exists():
        pytest.skip(f"robots/{name} not generated")
    robot = load_robot(ROBOTS / name)
    log = simulate(robot, duration=3.0)
    assert log.robot == name
    assert log.streams["pots"].data.shape == (300, len(robot.sensors.pots))
    truth = Calibration.from_dict(log.truth.params)
    s = pot_transmission(robot, log.truth.signals["q"].data)
    resid = log.streams["pots"].data - (truth.gain * s + truth.bias)
    assert resid.std() == pytest.approx(0.005, rel=0.15)


# ----------------------------------------------------------------------------- CLI
runner = CliRunner()


def _simulate_cli(out, *extra):
    """`diegocal simulate kinematics` of the tiny robot into ``out``, 5 s, with ``extra`` options."""
    args = ["simulate", "kinematics", "--robot", str(TINY), "-o", str(out), "--duration", "5", *extra]
    return runner.invoke(app, args)


def test_cli_writes_a_log_with_truth(tmp_path):
    out = tmp_path / "k.h5"
    res = _simulate_cli(
        out, "--seed", "3", "--effect", "backlash:elbow", "--occlusion", "0.2", "--marker-noise", "0.001"
    )
    assert res.exit_code == 0, res.output
    log = load_log(out)
    assert log.n_samples == 500 and log.robot == str(TINY.resolve())  # not bundled: its directory
    assert log.truth.effects[0]["cause"] == "backlash"
    assert log.truth.params["sigma"]["markers"] == 0.001
    out3 = tmp_path / "k3.h5"
    res = _simulate_cli(out3, "--effect", "link_offset:elbow=0.02", "--direction", "elbow:0:3:4")
    assert res.exit_code == 0, res.output
    np.testing.assert_allclose(load_log(out3).truth.effects[0]["values"]["dxyz"], [0.0, 0.012, 0.016])
    out2 = tmp_path / "k2.h5"
    res = _simulate_cli(out2, "--effect", "swapped_labels", "--effect", "marker_outliers:m_head")
    assert res.exit_code == 0, res.output
    back = load_log(out2)
    assert [e["cause"] for e in back.truth.effects] == ["swapped_labels", "marker_outliers"]
    assert back.truth.signals["markers_corrupted"].data.any()


@pytest.mark.parametrize(
    "args, message",
    [
        (["--effect", "wobble"], "not a kinematics effect"),
        (["--effect", "backlash:nope"], "'nope' is not a pot"),
        (["--effect", "marker_slip:m99"], "'m99' is not a marker"),
        (["--effect", "swapped_labels:m99"], "'m99' is not a marker"),
        (["--effect", "marker_outliers:elbow"], "'elbow' is not a marker"),
        (["--effect", "time_offset:pots"], "time_offset:markers"),
        (["--effect", "link_offset:shoulder=abc"], "is not a number"),
        (["--effect", "backlash:elbow=50"], "wider than the pot's range"),
        (["--effect", "link_offset:elbow", "--direction", "elbow:1:0"], "expected JOINT:DX:DY:DZ"),
        (["--duration", "-2"], "duration must be positive"),
        (["--occlusion", "1.5"], "occlusion fraction"),
        (["--robot", "/no/such/robot"], "not found"),
    ],
)
def test_cli_bad_input_is_one_clear_line(tmp_path, args, message):
    base_args = ["simulate", "kinematics", "--robot", str(TINY), "-o", str(tmp_path / "x.h5"), "--duration", "1"]
    res = runner.invoke(app, base_args + args)
    assert res.exit_code != 0
    assert message in res.output
    assert "Traceback" not in res.output
    assert not (tmp_path / "x.h5").exists()


def _variant(tmp_path, keep_pots: bool, keep_markers: bool) -> Path:
    import yaml

    sensors = yaml.safe_load((TINY / "sensors.yaml").read_text())
    sensors["pots"] = sensors["pots"] if keep_pots else []
    sensors["markers"] = sensors["markers"] if keep_markers else []
    (tmp_path / "robot.urdf").write_text((TINY / "robot.urdf").read_text())
    (tmp_path / "sensors.yaml").write_text(yaml.safe_dump(sensors))
    return tmp_path


def test_robot_with_markers_only_or_no_sensors(tmp_path):
    log = simulate(load_robot(_variant(tmp_path, False, True)), duration=2.0)
    assert set(log.streams) == {"markers"}
    with pytest.raises(EffectError, match="nothing it can act on"):
        simulate(load_robot(_variant(tmp_path, False, True)), duration=2.0, effects=["backlash"])
    bare = _variant(tmp_path, False, False)
    res = runner.invoke(
        app, ["simulate", "kinematics", "--robot", str(bare), "-o", str(tmp_path / "x.h5"), "--duration", "1"]
    )
    assert res.exit_code != 0 and "nothing to simulate" in res.output


@pytest.mark.parametrize("base_link", ["waist", "lower"])  # root base, and a base that moves
def test_batched_points_equal_the_library_loop(tmp_path, base_link):
    import yaml

    from diegocal.robot import marker_points
    from diegocal.sim.kinematics import base_points

    sensors = yaml.safe_load((TINY / "sensors.yaml").read_text())
    sensors["base_link"] = base_link
    (tmp_path / "robot.urdf").write_text((TINY / "robot.urdf").read_text())
    (tmp_path / "sensors.yaml").write_text(yaml.safe_dump(sensors))
    robot = load_robot(tmp_path)
    q = np.random.default_rng(1).uniform(robot.lower, robot.upper, (50, robot.n_joints))
    pts = marker_points(robot, np.random.default_rng(2).normal(0, 0.05, (5, 3)))
    np.testing.assert_allclose(base_points(robot, q, pts.links, pts.xyz), robot.points(q, pts), atol=1e-13)
