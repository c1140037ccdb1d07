"""The kinematics domain of ``diagnose`` (diegocal/diagnose/kinematics.py, diegocal/stac/terms.py).

Each cause is hidden by the kinematic simulator (its own physical shapes: a quadratic transfer
curve of s, a play operator on s, a moved joint origin, a shifted mocap clock, a marker moved at a
random time, ghost readings, swapped labels), on a random channel (the simulator's seeded choice)
with its default magnitude (3-20 x the channel's noise); the diagnosis never reads ``/truth``. The
TOP finding must name the cause and channel with a positive held-out gain; clean logs give none.
Fast cases use the bundled finger (7 pots, 5 markers, 30 s); the rest are ``slow``.
"""

from __future__ import annotations

import numpy as np
import pytest

from diegocal.diagnose import DiagnoseOptions, diagnose
from diegocal.diagnose.kinematics import KinematicsAdapter, _Lin
from diegocal.evaluate import split_blocks
from diegocal.robot import load_robot, resolve_robot_dir
from diegocal.sim.effects import parse_effect
from diegocal.sim.kinematics import KinematicsOptions, backlash, simulate_kinematics
from diegocal.stac.calibration import Calibration
from diegocal.stac.terms import apply_terms, direction, make_term, shift_clock, to_log_markers
from diegocal.terms import Region


@pytest.fixture(scope="module")
def finger():
    return load_robot(resolve_robot_dir("finger", None))


def _log(robot, seed, effects=(), duration=30.0):
    opts = KinematicsOptions(duration=duration, effects=tuple(parse_effect(e) for e in effects))
    return simulate_kinematics(robot, opts, np.random.default_rng(seed))


def _named(diagnosis, log) -> bool:
    """The top finding names the (first) injected cause and channel (a swap: the pair), with a
    positive held-out gain (faults: not negative)."""
    if not diagnosis.findings:
        return False
    top, truth = diagnosis.findings[0], log.truth.effects[0]
    if top.cause != truth["cause"]:
        return False
    if top.cause == "swapped_labels":
        if {top.channel, top.term.extra["partner"]} != {truth["channel"], truth["values"]["partner"]}:
            return False
    elif top.channel != truth["channel"]:
        return False
    red = top.gain()["reduction"]
    if top.cause == "link_offset":  # a joint may share its name with its pot: the markers' gain
        red = _pooled_reduction(top)
    return red > 0 or (top.kind == "fault" and red >= 0)


def _pooled_reduction(finding) -> float:
    """Held-out RMSE reduction pooled over the channels a finding acts on (its evidence)."""
    out = []
    for score in (finding.heldout_before, finding.heldout_after):
        idx = [score.channels.index(c) for c in finding.evidence["channels"]]
        n, r = score.n_samples[idx].astype(float), score.rmse[idx]
        out.append(np.sqrt(np.sum(r**2 * n) / n.sum()))
    return 1.0 - out[1] / out[0]


# ----------------------------------------------------------------------------- terms (cheap)
def test_direction_is_the_play_operator(finger):
    """A backlash regressor on the model's reading equals the simulator's play operator (two routes)."""
    rng = np.random.default_rng(0)
    x = np.cumsum(rng.normal(0, 0.01, 3000))
    width = 0.05
    dev = backlash(x, width) - x  # the simulator's dead band
    assert np.allclose(-direction(x, width) * width / 2, dev)


def test_shift_clock_round_trip():
    t = np.arange(200) / 100.0
    x = np.sin(3 * t)[:, None, None] * np.ones((1, 2, 3))
    y = shift_clock(shift_clock(x, t, 0.05), t, -0.05)
    ok = np.isfinite(y).all(axis=(1, 2))
    assert ok.sum() > 180
    assert np.max(np.abs(y[ok] - x[ok])) < 2e-3  # linear interpolation of a smooth path


def test_calibration_terms_yaml_round_trip(finger):
    cal = Calibration.nominal(finger)
    terms = (
        make_term("sensor_nonlinearity", "fdp", [0.05, -0.01], extra={"center": 2.0, "half": 1.0}),
        make_term("marker_outliers", "m2", extra={"frames": {"m2": [3, 4]}}),
    )
    from dataclasses import replace

    back = Calibration.from_dict(replace(cal, terms=terms).to_dict())
    assert [t.cause for t in back.terms] == ["sensor_nonlinearity", "marker_outliers"]
    assert np.allclose(back.terms[0].values, [0.05, -0.01])
    assert back.terms[1].extra["frames"] == {"m2": [3, 4]}
    assert "terms" not in cal.to_dict()  # STAC's own calib.yaml is unchanged


def test_slip_split_and_merged_back(finger):
    """A slipped marker is split into two markers and merged back on the log's clock."""
    log = _log(finger, 1, duration=4.0)
    slip = make_term("marker_slip", "m3", [0.01, 0.0, 0.0], region=Region("time", 2.0, 4.0))
    a = apply_terms((slip,), log.without_truth(), finger)
    names = a.log.stream("markers").names
    assert "m3~slip" in names and "m3~slip" in a.robot.sensors.marker_names
    x = a.log.stream("markers").data
    back = to_log_markers(a, names, x)
    assert np.array_equal(np.isnan(back), np.isnan(log.stream("markers").data))
    assert np.allclose(np.nan_to_num(back), np.nan_to_num(log.stream("markers").data))


# ----------------------------------------------------------------------------- the adapter
@pytest.fixture(scope="module")
def baseline(finger):
    log = _log(finger, 3, ("sensor_nonlinearity",), duration=20.0)
    blocks = split_blocks(log.n_samples, 10)
    adapter = KinematicsAdapter(log, finger)
    return adapter, adapter.fit((), blocks.mask("train")), blocks


def test_schur_projection_is_orthogonal_to_q(baseline):
    """Projected candidate columns carry nothing a change of the frame's q could explain:
    Jᵀ W c = 0 per frame (the Schur complement of the brief)."""
    adapter, fitted, _ = baseline
    lin = _Lin.at(fitted, adapter)
    raw_g = np.zeros((lin.T, lin.R, 1))
    raw_g[:, 0, 0] = 1.0
    raw_c = lin.link_offset_basis("dip")
    for raw in (raw_g, raw_c):
        before = np.einsum("trn,tr,trk->tnk", lin.J, lin.w, raw)
        after = np.einsum("trn,tr,trk->tnk", lin.J, lin.w, lin.project(raw))
        assert np.abs(before).max() > 0
        assert np.abs(after).max() < 1e-8 * np.abs(before).max()
    assert np.allclose(lin.project_pot(0), lin.project(raw_g)[..., 0])


def test_residual_channels_and_variables(baseline):
    adapter, fitted, _ = baseline
    res = adapter.residuals(fitted)
    assert set(res.channels) == set(adapter.pot_names) | set(adapter.marker_names)
    assert res.channels["m1"].shape == (adapter.time.size, 3) and res.units["m1"] == "m"
    assert res.channels["fdp"].shape == (adapter.time.size,) and res.units["fdp"] == "V"
    assert "q.dip" in res.variables and "p.dip" in res.variables and "time" in res.variables
    assert res.channel_variables["dip"][0] == "p.dip"


# ----------------------------------------------------------------------------- naming (fast)
def test_clean_log_gives_no_findings(finger):
    log = _log(finger, 12, duration=20.0)
    d = diagnose(log, finger, DiagnoseOptions(domain="kinematics"))
    assert d.findings == ()


def test_sensor_nonlinearity_named_and_predict_uses_it(finger, tmp_path):
    from typer.testing import CliRunner

    from diegocal.cli.app import app
    from diegocal.io import load_yaml, save_log

    log = _log(finger, 10, ("sensor_nonlinearity",))
    d = diagnose(log, finger, DiagnoseOptions(domain="kinematics"))
    assert _named(d, log), [(f.cause, f.channel, f.gain()) for f in d.findings]
    top = d.findings[0]
    peak = log.truth.effects[0]["values"]["peak"]
    assert abs(top.term.value("c2") - peak) < 0.3 * abs(peak)  # c2 u² at the range's ends
    ext = d.save_extended(tmp_path / "x.extended.calib.yaml", {"kind": "calibration", "command": "test"})
    data = load_yaml(ext)
    assert data["kind"] == "calibration" and data["terms"][0]["cause"] == "sensor_nonlinearity"
    path = tmp_path / "log.h5"
    save_log(log, path)
    out = CliRunner().invoke(app, ["predict", str(ext), str(path), "--from", "pots", "--to", "markers", "-q"])
    assert out.exit_code == 0, out.output
    assert (tmp_path / "log.prediction.h5").is_file()


def test_marker_outliers_are_a_fault(finger):
    log = _log(finger, 10, ("marker_outliers",), duration=20.0)
    d = diagnose(log, finger, DiagnoseOptions(domain="kinematics"))
    assert _named(d, log)
    top = d.findings[0]
    truth = log.truth.signals["markers_corrupted"].data.astype(bool)
    names = log.stream("markers").names
    found = np.zeros_like(truth)
    for m, frames in top.term.extra["frames"].items():
        found[frames, names.index(m)] = True
    assert (found & truth).sum() >= 0.8 * truth.sum()  # most ghosts named
    assert (found & ~truth).sum() <= 0.05 * found.sum()  # few good readings called ghosts


# ----------------------------------------------------------------------------- naming (slow)
CASES = [
    ("sensor_nonlinearity", (10, 12, 13)),
    ("backlash", (0, 1, 2, 3, 10)),
    ("time_offset", (10, 11, 12)),
    ("marker_slip", (10, 12, 13)),
    ("swapped_labels", (10, 11, 12, 13)),
]


@pytest.mark.slow
@pytest.mark.parametrize("cause,seed", [(c, s) for c, seeds in CASES for s in seeds])
def test_cause_named_slow(finger, cause, seed):
    log = _log(finger, seed, (cause,))
    d = diagnose(log, finger, DiagnoseOptions(domain="kinematics"))
    assert _named(d, log), [(f.cause, f.channel, f.gain()) for f in d.findings]
    if cause == "marker_slip":  # the slip time within one block (the training blocks' resolution)
        t0 = log.truth.effects[0]["region"]["low"]
        assert abs(d.findings[0].term.region.low - t0) <= log.duration / 10


@pytest.mark.slow
@pytest.mark.parametrize("joint,seed", [("pip", 3), ("dip", 3)])
def test_link_offset_named_slow(finger, joint, seed):
    """A joint's origin off by 5-10 mm, on a joint whose parent frame turns (an offset of a joint
    hanging from the base is a shift of the mocap frame: not identifiable)."""
    log = _log(finger, seed, (f"link_offset:{joint}",), duration=60.0)
    d = diagnose(log, finger, DiagnoseOptions(domain="kinematics"))
    assert _named(d, log), [(f.cause, f.channel, f.gain()) for f in d.findings]


@pytest.mark.slow
def test_two_effects_both_found(finger):
    log = _log(finger, 12, ("sensor_nonlinearity", "time_offset"))
    d = diagnose(log, finger, DiagnoseOptions(domain="kinematics"))
    found = {(f.cause, f.channel) for f in d.findings}
    for e in log.truth.effects:
        assert (e["cause"], e["channel"]) in found, found


@pytest.mark.slow
def test_ur5_from_example_robot_data(tmp_path):
    """A robot diegocal did not design (tests/erd.py: a pot on every joint, markers on every
    other link): a pot's nonlinearity named on it too."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).parents[1]))
    from erd import robot_dir

    robot = load_robot(robot_dir(tmp_path, "ur5"))
    log = _log(robot, 1, ("sensor_nonlinearity",))
    d = diagnose(log, robot, DiagnoseOptions(domain="kinematics"))
    assert _named(d, log), [(f.cause, f.channel, f.gain()) for f in d.findings]
