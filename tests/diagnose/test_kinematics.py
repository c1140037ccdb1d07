"""The kinematics domain of ``diagnose`` (diegocal/diagnose/kinematics.py, diegocal/stac/terms.py).

Each cause is hidden by the kinematic simulator (its own physical shapes: a quadratic transfer
curve of s, a play operator on s, a moved joint origin, a shifted mocap clock, a marker moved at a
random time, ghost readings, swapped labels), on a random channel (the simulator's seeded choice)
with its default magnitude (3-20 x the channel's noise) or a size of 3-10 x it; the diagnosis never
reads ``/truth``. The TOP finding must name the cause and channel with a positive held-out gain;
clean logs give none. Fast cases use the bundled finger (7 pots, 5 markers, 30 s); the rest are
``slow``. Robots diegocal did not design: UR5 and Panda from example-robot-data (tests/erd.py: a
pot on every revolute joint, markers on every other link and the last, so that every joint moves
some marker).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from diegocal import progress
from diegocal.diagnose import DiagnoseOptions, diagnose, kinematics_sweep
from diegocal.diagnose.kinematics import KinematicsAdapter
from diegocal.diagnose.kinematics_sweep import Columns, Sweep, whole_log
from diegocal.evaluate import split_blocks
from diegocal.io.log import Stream
from diegocal.progress import Eta
from diegocal.robot import load_robot, resolve_robot_dir
from diegocal.sim.effects import parse_effect
from diegocal.sim.kinematics import KinematicsOptions, backlash, simulate_kinematics
from diegocal.stac import loo
from diegocal.stac.calibration import Calibration
from diegocal.stac.terms import apply_terms, direction, shift_clock, to_log_markers
from diegocal.terms import Region, make_term


@pytest.fixture(scope="module")
def finger():
    return load_robot(resolve_robot_dir("finger", None))


def _log(robot, seed, effects=(), duration=30.0, along_link=()):
    """A simulated log; a link offset on a joint of ``along_link`` moves its origin along the link
    (the direction of its URDF origin: the link is longer or shorter)."""
    dirs = {j: tuple(robot.model.jointPlacements[robot.model.getJointId(j)].translation) for j in along_link}
    opts = KinematicsOptions(duration=duration, effects=tuple(parse_effect(e) for e in effects), directions=dirs)
    return simulate_kinematics(robot, opts, np.random.default_rng(seed))


def _named(diagnosis, log) -> bool:
    """The top finding names the (first) injected cause and channel (a swap: the pair), with a
    positive held-out gain."""
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
    return red > 0


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


def test_slip_time_scan_equals_brute_force_refits():
    """The change-point scan of a slip (prefix sums) picks, in each training run, the change time
    a least-squares refit before and after every time picks; a slip inside a gap is its middle,
    first and last frame (the training frames cannot tell them apart), the middle listed first."""
    from diegocal.diagnose.kinematics_slip import slip_samples as _slip_samples

    rng = np.random.default_rng(3)
    T, R = 400, 6
    train = np.zeros(T, bool)
    train[:150], train[200:300], train[340:] = True, True, True
    cols = rng.normal(size=(T, R, 3))
    w = rng.uniform(0.5, 2.0, size=(T, R)) * train[:, None]

    def brute(r, a, e):
        sse = []
        for k in range(a + 1, e):
            A = np.concatenate([cols, cols * (np.arange(T) >= k)[:, None, None]], axis=-1)
            sw = np.sqrt(w)[train].reshape(-1)
            Aw, rw = A[train].reshape(-1, 6) * sw[:, None], r[train].reshape(-1) * sw
            sse.append(np.sum((rw - Aw @ np.linalg.lstsq(Aw, rw, rcond=None)[0]) ** 2))
        return a + 1 + int(np.argmin(sse))

    for k0 in (237, 170):  # inside the second run; inside the gap before it
        r = cols @ np.array([1.0, -2.0, 0.5]) * (np.arange(T) >= k0)[:, None] + 0.3 * rng.normal(size=(T, R))
        got = _slip_samples(train, cols, r, w)
        want = [brute(r, 0, 150), 175, 150, 199, brute(r, 200, 300), 320, 300, 339, brute(r, 340, 400)]
        assert got == list(dict.fromkeys(k for k in want if 20 <= k <= 380))  # not in the first or last 5 %
        assert (k0 in got) if train[k0] else (175 in got and brute(r, 200, 300) == 201)


def test_schur_projection_is_orthogonal_to_q(baseline):
    """Projected candidate columns carry nothing a change of the frame's q could explain:
    Jᵀ W c = 0 per frame (the Schur complement of the brief)."""
    adapter, fitted, _ = baseline
    lin = whole_log(fitted, adapter)
    raw_g = np.zeros((lin.T, lin.R, 1))
    raw_g[:, 0, 0] = 1.0
    raw_c = lin.link_offset_basis("dip")
    for raw in (raw_g, raw_c):
        before = np.einsum("trn,tr,trk->tnk", lin.J, lin.w, raw)
        after = np.einsum("trn,tr,trk->tnk", lin.J, lin.w, lin.project(raw))
        assert np.abs(before).max() > 0
        assert np.abs(after).max() < 1e-8 * np.abs(before).max()
    assert np.allclose(lin.project_pot(0), lin.project(raw_g)[..., 0])


def test_deleted_residuals_are_leave_one_sensor_out_refits(baseline, monkeypatch):
    """Each sensor's deleted residual is its reading against the frame's q refitted without it
    (weighted least squares on the linearised frame), also where the fit's q does not solve the
    normal equations (a pot whose σ collapsed pinned its joint: its own residual ~0 whatever the
    other sensors say). Residuals are replaced by random ones to make Jᵀ W r ≠ 0."""
    adapter, fitted, _ = baseline
    lin = whole_log(fitted, adapter)
    r = np.random.default_rng(0).normal(0.0, 0.01, (lin.T, lin.R))
    monkeypatch.setattr(lin, "residual_rows", lambda: r)
    rp, rm = lin.deleted_residuals()
    for t in (0, lin.T // 2, lin.T - 1):
        J, w = lin.J[t], lin.w[t]
        H = J.T @ (w[:, None] * J) + np.diag(lin.D[t])
        rows = {i: [i] for i in range(lin.P)} | {
            lin.P + m: list(range(lin.P + 3 * m, lin.P + 3 * m + 3)) for m in range((lin.R - lin.P) // 3)
        }
        for key, idx in rows.items():
            keep = np.setdiff1d(np.arange(lin.R), idx)
            Hk = H - J[idx].T @ (w[idx, None] * J[idx])
            dq = np.linalg.solve(Hk, J[keep].T @ (w[keep] * r[t, keep]))
            loo = r[t, idx] - J[idx] @ dq
            got = rp[t, key] if key < lin.P else rm[t, key - lin.P]
            if np.all(np.isfinite(got)):
                np.testing.assert_allclose(got, loo, rtol=1e-6, atol=1e-9)


def test_deleted_residuals_a_batch_at_a_time_equal_the_whole_log(baseline, monkeypatch):
    """``predict --from others`` takes the deleted residuals a batch of frames at a time
    (:func:`~diegocal.stac.loo.deleted_from_others`, no frame's J and K held past its batch): the
    same numbers as every frame's projection at once, with batches that do not divide the log,
    and the same bits with the batches in two threads."""
    adapter, fitted, _ = baseline
    lin = whole_log(fitted, adapter)
    r = np.random.default_rng(1).normal(0.0, 0.01, (lin.T, lin.R))
    sigma = loo.sigma_of(fitted.cal)
    want = loo.deleted_residuals(loo.frame_projection(lin.obs, lin.params, sigma, fitted.q), r, lin.P)
    monkeypatch.setattr(loo, "BATCH", 37)
    assert lin.T % 37
    got = loo.deleted_from_others(lin.obs, lin.params, sigma, fitted.q, r)
    for g, w in zip(got, want, strict=True):
        np.testing.assert_allclose(g, w, rtol=1e-12, atol=1e-15)
    threads = loo.deleted_from_others(lin.obs, lin.params, sigma, fitted.q, r, jobs=2)  # batches in threads
    for g, t in zip(got, threads, strict=True):
        np.testing.assert_array_equal(t, g)
    proj = loo.frame_projection(lin.obs, lin.params, sigma, fitted.q)  # filled batch by batch
    np.testing.assert_allclose(proj.J, lin.J, rtol=0, atol=0)
    K = lin.K  # from the linearisation's (JᵀWJ + D)⁻¹
    np.testing.assert_allclose(proj.K, K, rtol=1e-9, atol=1e-9 * np.abs(K).max())


def test_a_sweep_makes_each_block_once_and_reads_it_back_on_the_next_passes(baseline, monkeypatch):
    """The forward kinematics, Jacobians and inverses of a block are made on the first pass over it
    only; the next passes read the very numbers back (:class:`~diegocal.diagnose.spill.BlockStore`)."""
    adapter, fitted, _ = baseline
    made = []
    project = kinematics_sweep.batch_projection
    monkeypatch.setattr(kinematics_sweep, "batch_projection", lambda *a, **k: made.append(1) or project(*a, **k))
    sweep = Sweep(fitted, adapter)
    first = [(b.J, b.Hi, b.w) for b in sweep.blocks()]
    again = [(b.J, b.Hi, b.w) for b in sweep.blocks()]
    assert len(made) == len(sweep.slices) > 1
    for a, b in zip(first, again, strict=True):
        for x, y in zip(a, b, strict=True):
            np.testing.assert_array_equal(x, y)


def test_calibration_span_from_its_structure_equals_the_dense_basis(baseline):
    """Fᵀ V, F β and (S F)ᵀ W (S F) from F's structure equal the same products with F written out
    (two routes; F: every pot's gain and bias, every marker's position, the mocap frame)."""
    adapter, fitted, _ = baseline
    lin = whole_log(fitted, adapter)
    F = lin._calibration_basis(slice(0, lin.T))
    rng = np.random.default_rng(0)
    V = rng.normal(size=(lin.T, lin.R, 2))
    assert np.allclose(lin._calibration_dot(V), np.einsum("trk,trl->kl", F, V), rtol=1e-10, atol=1e-9)
    beta = rng.normal(size=(F.shape[-1], 2))
    assert np.allclose(lin._calibration_apply(beta), F @ beta, rtol=1e-10, atol=1e-12)
    SF = F - lin.J @ (lin.K @ F)
    wt = lin.w * fitted.train[:, None]
    dense = np.einsum("trk,tr,trl->kl", SF, wt, SF)
    assert np.abs(lin._gram() - dense).max() < 1e-8 * np.abs(dense).max()


def test_fitting_beyond_the_calibration_equals_refitting_it(baseline):
    """Frisch-Waugh-Lovell: a term's columns with the (projected) calibration directions fitted out
    explain of a residual orthogonal to those directions exactly what the term and the whole
    calibration re-fitted together explain; and the baseline's residual is that orthogonal (STAC's
    fit is the calibration's optimum) up to its convergence."""
    adapter, fitted, _ = baseline
    lin = whole_log(fitted, adapter)
    r = np.nan_to_num(lin.residual_rows())
    rows = fitted.train[:, None] & (lin.w > 0)
    sw = np.sqrt(lin.w[rows])

    def sse(A, y):
        coef = np.linalg.lstsq(A[rows] * sw[:, None], y[rows] * sw, rcond=None)[0]
        return np.sum(lin.w[rows] * (y[rows] - A[rows] @ coef) ** 2)

    F = lin._calibration_basis(slice(0, lin.T))
    SF = F - lin.J @ (lin.K @ F)
    coef = np.linalg.lstsq(SF[rows] * sw[:, None], r[rows] * sw, rcond=None)[0]
    r_perp = r - SF @ coef  # the residual with the calibration re-fitted
    before = np.sum(lin.w[rows] * r[rows] ** 2)
    assert before - np.sum(lin.w[rows] * r_perp[rows] ** 2) < 1e-3 * before  # STAC's optimum
    C = lin.project(lin.link_offset_basis("dip"))
    assert sse(lin.beyond_calibration(C), r_perp) == pytest.approx(sse(np.concatenate([C, SF], axis=-1), r), rel=1e-9)


def test_link_offsets_the_calibration_takes_up_are_no_candidates(baseline):
    """On the finger (flexion axes parallel, y) a joint's origin moved along the axis is the markers'
    positions below it, and moved across the link a pot bias (angle offsets of the joint and its
    parent): only the link's length (x) is left; mcp_abd hangs from the base (the mocap frame)."""
    adapter, fitted, _ = baseline
    lin = whole_log(fitted, adapter)
    wt = lin.w * fitted.train[:, None]
    assert not np.any(lin.beyond_calibration(lin.project(lin.link_offset_basis("mcp_abd"))))
    for joint in ("pip", "dip"):
        C = lin.beyond_calibration(lin.project(lin.link_offset_basis(joint)))
        lam, V = np.linalg.eigh(np.einsum("trk,tr,trl->kl", C, wt, C))
        assert np.sum(lam > 1e-9 * lam.max()) == 1
        assert abs(V[0, -1]) > 0.99  # the one direction left: x, along the link


def test_a_sweep_block_by_block_equals_the_whole_log(baseline, monkeypatch):
    """A round's columns made a block of frames at a time (:class:`Sweep`: the fit's sums, then the
    orthogonalised columns' Gram matrices, then the columns; blocks that do not divide the log,
    a few sets projected together) equal those of every frame's linearisation at once: projected,
    the calibration fitted out, the directions it takes up zeroed (mcp_abd: all of them, no
    columns), in float32 on the channels that carry them."""
    adapter, fitted, _ = baseline
    monkeypatch.setattr(kinematics_sweep, "SWEEP_FRAMES", 37)
    monkeypatch.setattr(kinematics_sweep, "PROJECT_COLUMNS", 4)
    lin = whole_log(fitted, adapter)
    sweep = Sweep(fitted, adapter)
    assert sweep.T % 37
    joints = sweep.observed_joints()
    cols = [Columns(lambda b, j=j: b.link_offset_basis(j)) for j in joints]
    got = sweep.channels(cols)
    assert got[joints.index("mcp_abd")] is None
    for joint, g in zip(joints, got, strict=True):
        want = lin.beyond_calibration(lin.project(lin.link_offset_basis(joint)))
        assert (g is None) == (not np.any(want))
        for name, x in (g or {}).items():  # a pot (T, 3) or a marker (T, 3, 3)
            if name in adapter.pot_names:
                rows = want[:, adapter.pot_names.index(name)]
            else:
                m = sweep.mapped_index(name)
                rows = want[:, lin.P + 3 * m : lin.P + 3 * m + 3]
            assert x.dtype == np.float32
            np.testing.assert_allclose(x, rows, atol=1e-6 * np.abs(want).max())


def test_a_steps_design_in_two_passes_equals_the_whole_log(baseline, monkeypatch):
    """A Gauss-Newton step's columns (:meth:`Sweep.design`: the fits' sums, then the columns, the
    identifiable directions from raw − bᵀ G⁺ b instead of a pass of their own) equal every frame's
    linearisation at once on the training frames: mcp_abd's offset, which the calibration takes up
    entirely, zero."""
    adapter, fitted, _ = baseline
    monkeypatch.setattr(kinematics_sweep, "SWEEP_FRAMES", 37)
    lin = whole_log(fitted, adapter)
    sweep = Sweep(fitted, adapter, train_only=True)
    joints = sweep.observed_joints()
    cols = [Columns(lambda b, j=j: b.link_offset_basis(j)) for j in joints]
    got = np.zeros((sweep.T, lin.R, 3 * len(joints)))
    sweep.design(cols, lambda b, C: got.__setitem__(b.frames, C))
    want = np.concatenate([lin.beyond_calibration(lin.project(lin.link_offset_basis(j))) for j in joints], axis=-1)
    train = fitted.train
    abd = 3 * joints.index("mcp_abd")
    assert not np.any(got[:, :, abd : abd + 3])
    # raw − bᵀ G⁺ b cancels to ~1e-9 of raw: the kept directions turn by ~1e-8 (a step's tolerance: 0.2 SE)
    np.testing.assert_allclose(got[train], want[train], atol=1e-6 * np.abs(want).max())


def test_a_sweep_in_threads_equals_one_thread(baseline, monkeypatch):
    """``--jobs 2``: the next blocks' columns made in threads while this block's are read give the
    same numbers, bit for bit (the same calls in the same order), in every pass."""
    adapter, fitted, _ = baseline
    monkeypatch.setattr(kinematics_sweep, "SWEEP_FRAMES", 53)
    joints = Sweep(fitted, adapter).observed_joints()
    cols = [Columns(lambda b, j=j: b.link_offset_basis(j)) for j in joints]
    got = {}
    for jobs in (1, 2):
        sweep = Sweep(fitted, adapter)
        sweep.jobs = jobs
        designs = []
        sweep.design(cols, lambda lin, C, out=designs: out.append((lin.frames, C.copy())))
        got[jobs] = (sweep.channels(cols), designs)
    (one, d1), (two, d2) = got[1], got[2]
    assert len(d1) == len(d2) > 3
    for (f1, c1), (f2, c2) in zip(d1, d2, strict=True):
        assert f1 == f2
        np.testing.assert_array_equal(c1, c2)
    for a, b in zip(one, two, strict=True):
        assert (a is None) == (b is None)
        for name in a or {}:
            np.testing.assert_array_equal(a[name], b[name])


def test_a_sweep_says_how_far_its_passes_are(baseline, monkeypatch):
    """A long log's sweep takes minutes: each block of each of the three passes is counted, with
    the time left."""
    adapter, fitted, _ = baseline
    monkeypatch.setattr(kinematics_sweep, "SWEEP_FRAMES", 211)
    monkeypatch.setattr(progress, "Eta", lambda total: Eta(total, every=0.0))  # every block
    said = []
    monkeypatch.setattr(adapter, "progress", said.append)
    sweep = Sweep(fitted, adapter)
    joints = sweep.observed_joints()
    sweep.channels([Columns(lambda b, j=j: b.link_offset_basis(j)) for j in joints])
    n = len(sweep.trained) + 2 * -(-sweep.T // 211)  # the first pass: the blocks with training frames
    assert len(sweep.trained) < len(sweep.slices)
    assert len(said) == n
    assert said[-1].startswith(f"candidate columns, 3 passes over blocks of 211 frames: {n}/{n}")
    assert "left" in said[0]


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
    """Named first; a data fault whose writing-off removes under ``min_gain`` (seed 10's swap of 116
    frames: 0.4 % of the held-out error) is found as a minor fault on its pair instead, written
    off, with no finding."""
    log = _log(finger, seed, (cause,))
    d = diagnose(log, finger, DiagnoseOptions(domain="kinematics"))
    truth = log.truth.effects[0]
    pair = {truth["channel"], truth["values"].get("partner")}
    minor = [f for u in d.units for f in u.minor_faults if f.cause == cause and f.evidence["written_off"]]
    if not d.findings and minor and cause == "swapped_labels":
        assert {minor[0].channel, minor[0].term.extra["partner"]} == pair
        return
    assert _named(d, log), [(f.cause, f.channel, f.gain()) for f in d.findings]
    if cause == "marker_slip":  # the slip time within one block (the training blocks' resolution)
        t0 = log.truth.effects[0]["region"]["low"]
        assert abs(d.findings[0].term.region.low - t0) <= log.duration / 10


@pytest.mark.slow
@pytest.mark.parametrize("joint,size,seed", [("mcp_flex", 0.012, 1), ("pip", 0.008, 2), ("dip", 0.006, 3)])
def test_link_offset_named_slow(finger, joint, size, seed):
    """A link 3-6 x the marker noise longer or shorter than the URDF says, on a joint whose parent
    frame turns (an offset of a joint hanging from the base is a shift of the mocap frame, and the
    other directions are the markers' and pots' own: not identifiable); its value within 20 %."""
    log = _log(finger, seed, (f"link_offset:{joint}={size}",), along_link=(joint,))
    d = diagnose(log, finger, DiagnoseOptions(domain="kinematics"))
    assert _named(d, log), [(f.cause, f.channel, f.gain()) for f in d.findings]
    assert np.linalg.norm(d.findings[0].term.values) == pytest.approx(size, rel=0.2)


@pytest.mark.slow
def test_a_clock_shift_of_many_samples_is_named_slow(finger):
    """0.15 s (RMS marker displacement ~4 x the noise): the markers' change over the shift, not its
    linearisation at zero, is what a family variant fits."""
    log = _log(finger, 4, ("time_offset:markers=0.15",))
    d = diagnose(log, finger, DiagnoseOptions(domain="kinematics"))
    assert _named(d, log), [(f.cause, f.channel, f.gain()) for f in d.findings]
    assert d.findings[0].term.values[0] == pytest.approx(log.truth.effects[0]["values"]["seconds"], abs=0.03)


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


@pytest.mark.slow
def test_panda_from_example_robot_data(tmp_path):
    """A second robot diegocal did not design (tests/erd.py, markers on links 2, 4, 6 and 7): its
    forearm (joint 4's origin, 8.25 cm from joint 3) 1 cm longer is named with its length; a clean
    log of it gives nothing."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).parents[1]))
    from erd import robot_dir

    robot = load_robot(robot_dir(tmp_path, "panda"))
    log = _log(robot, 2, ("link_offset:panda_joint4=0.01",), along_link=("panda_joint4",))
    d = diagnose(log, robot, DiagnoseOptions(domain="kinematics"))
    assert _named(d, log), [(f.cause, f.channel, f.gain()) for f in d.findings]
    assert np.linalg.norm(d.findings[0].term.values) == pytest.approx(0.01, rel=0.1)
    assert diagnose(_log(robot, 1), robot, DiagnoseOptions(domain="kinematics")).findings == ()


def test_a_slip_region_is_open(baseline, finger):
    """A marker that slipped stays moved: the slip candidates' regions (and the simulator's truth)
    run from the change time on without end, so a calibration with the term predicts a later log
    on the same clock with the marker moved throughout."""
    adapter, fitted, blocks = baseline
    train = blocks.mask("train")
    cands = [c for c in adapter.candidates(fitted, adapter.residuals(fitted), train) if c.term.cause == "marker_slip"]
    assert cands and all(c.term.region.high == np.inf and c.term.region.low < adapter.time[-1] for c in cands)
    log = _log(finger, 2, ("marker_slip",), duration=4.0)
    assert log.truth.effects[0]["region"]["high"] == np.inf
    later = log.without_truth()
    from dataclasses import replace

    later = replace(later, time=later.time + 100.0)
    slip = make_term("marker_slip", "m3", [0.01, 0.0, 0.0], region=Region("time", 2.0, np.inf))
    x = apply_terms((slip,), later, finger).log.stream("markers")
    assert np.isnan(x.column("m3")).all() and not np.isnan(x.column("m3~slip")).all()


@pytest.mark.parametrize("cause,seed", [("time_offset", 21), ("time_offset", 22), ("sensor_nonlinearity", 23)])
def test_a_fitted_term_has_standard_errors_that_cover_the_truth(finger, cause, seed):
    """A term the adapter fits (the Gauss-Newton step of its refinement) carries standard errors:
    the block sandwich of that step's least squares (the residuals are correlated in time), at
    least the model-based ones; the simulator's truth lies within 3 of them (a clock shift's
    seconds; a quadratic transfer curve's c2 at the ends of the term's range, and c3 = 0)."""
    log = _log(finger, seed, (cause,), duration=20.0)
    adapter = KinematicsAdapter(log, finger)
    effect = log.truth.effects[0]
    term = adapter.fit((make_term(cause, effect["channel"]),), split_blocks(log.n_samples, 10).mask("train")).terms[0]
    if cause == "time_offset":
        truth = [effect["values"]["seconds"]]
    else:
        cal = Calibration.from_dict(log.truth.params)
        g = cal.gain[cal.pot_names.index(effect["channel"])]
        truth = [effect["values"]["c2"] * (term.extra["half"] / g) ** 2, 0.0]
    assert np.all(np.isfinite(term.stderrs)) and np.all(term.stderrs > 0)
    z = (term.values - truth) / term.stderrs
    assert np.all(np.abs(z) < 3.0), z


def test_a_slip_inside_a_heldout_block_is_scored_where_its_start_is_known(finger):
    """The slip starts at 13.05 s, inside the held-out block 12-15 s: no training frame places
    it there, so the fit starts it in the block's middle and the finding's held-out gain leaves
    that block out (scored on it, a wrong half-block costs what the rest gains: 30 %, not 58 %)."""
    log = _log(finger, 0, ("marker_slip",))
    d = diagnose(log, finger, DiagnoseOptions(domain="kinematics"))
    assert _named(d, log)
    top = d.findings[0]
    assert top.evidence["heldout_leaves_out"] == pytest.approx([12.0, 14.99])
    assert top.gain()["reduction"] > 0.5


def test_a_slip_at_a_training_blocks_end_is_named_on_its_marker(tmp_path):
    """A user trial's TALOS arm (experiments/kinematics_generator.py): a 12-mm slip at 13.96 s, the
    last frames of a training block before a validation block. The gap's middle (15.0 s) was the
    only start tried there: half the validation block uncorrected, t under the threshold, and five
    1-mm slips on markers that never moved named instead. The gap's first frame is tried too."""
    from experiments import kinematics_generator as kg

    sys.path.insert(0, str(Path(__file__).parents[1]))
    from erd import robot_dir

    rdir = robot_dir(tmp_path, "talos_arm")
    log = kg.generate(kg.Session(robot=rdir, duration=20.0, cause="marker_slip", seed=6, hardware_seed=34))
    d = diagnose(log.without_truth(), load_robot(rdir), DiagnoseOptions(domain="kinematics"))
    truth = log.truth.effects[0]
    assert [(f.cause, f.channel) for f in d.findings] == [("marker_slip", truth["channel"])]
    moved = np.linalg.norm([p.value for p in d.findings[0].term.parameters])
    assert abs(moved - np.linalg.norm(truth["values"]["dxyz"])) < 0.002


def test_a_swap_with_a_marker_the_cameras_lost_is_found(finger):
    """Two labels swapped while one of the markers is not seen: the other's reading sits on the
    lost marker's predicted place (its prediction, not its missing reading, is compared)."""
    log = _log(finger, 11, ("swapped_labels",), duration=20.0)
    truth = log.truth.effects[0]
    a, b = truth["channel"], truth["values"]["partner"]
    markers = log.stream("markers")
    frames = np.flatnonzero(log.truth.signals["markers_corrupted"].data[:, markers.index(a)].astype(bool))
    data = markers.data.copy()
    data[frames, markers.index(b)] = np.nan  # the partner lost in every swapped frame
    log = log.with_streams(markers=Stream(markers.names, data)).without_truth()
    adapter = KinematicsAdapter(log, finger)
    fitted = adapter.fit((), split_blocks(log.n_samples, 10).mask("train"))
    swaps = [f for f in adapter.faults(fitted, adapter.residuals(fitted)) if f.term.cause == "swapped_labels"]
    assert [{f.term.channel, f.term.extra["partner"]} for f in swaps] == [{a, b}]
    assert len(set(swaps[0].term.extra["frames"]) & set(frames)) >= 0.9 * len(frames)


def test_a_slip_in_a_gauge_says_what_the_data_fix_of_it(finger):
    """m4 rides on the distal link, whose zero (dip's) the calibration fixes by convention: its
    slip's components are placed turned about dip's axis (here x 13 standard errors from the
    truth), so the term carries ``extra.gauge``: the length and the component along the axis,
    which that turn leaves alone, and which cover the truth."""
    log = _log(finger, 2, ("marker_slip:m4",), duration=20.0)
    v = log.truth.effects[0]["values"]
    t0 = v["time"] + 0.5 * v.get("transition_s", 0.0)
    region = Region("time", float(log.time[np.searchsorted(log.time, t0)]), np.inf)
    adapter = KinematicsAdapter(log.without_truth(), finger)
    train = split_blocks(log.n_samples, 10).mask("train")
    term = adapter.fit((make_term("marker_slip", "m4", region=region),), train).terms[0]
    truth = np.array(v["dxyz"])
    assert np.abs((term.values - truth) / term.stderrs).max() > 5  # the components: in the gauge
    g = term.extra["gauge"]
    assert g["joint"] == "dip" and np.allclose(g["axis"], [0.0, 1.0, 0.0])
    assert abs(g["length"]["value"] - np.linalg.norm(truth)) < 3 * g["length"]["stderr"]
    assert abs(g["along_axis"]["value"] - truth[1]) < 3 * g["along_axis"]["stderr"]


def test_a_gauge_slips_length_and_along_axis_errors_come_from_the_full_covariance():
    """An error that lies along the turn about the axis (perpendicular to the move and the axis)
    changes neither the length nor the component along the axis: their ± are then zero, where
    the coordinates' ± taken apart would give them the turn's size; never below the model-based
    covariance's (the second)."""
    from diegocal.diagnose.kinematics_slip import slip_gauge

    axis, d = np.array([0.0, 1.0, 0.0]), np.array([0.01, 0.0, 0.0])
    turn = np.cross(axis, d) / np.linalg.norm(d)  # (0, 0, -1)
    g = slip_gauge("dip", axis, d, np.stack([1e-6 * np.outer(turn, turn)] * 2))
    assert g["length"]["value"] == pytest.approx(0.01) and g["length"]["stderr"] < 1e-12
    assert g["along_axis"]["stderr"] < 1e-12
    g = slip_gauge("dip", axis, d, np.stack([1e-6 * np.outer(turn, turn), 1e-6 * np.eye(3)]))
    assert g["length"]["stderr"] == pytest.approx(1e-3) and g["along_axis"]["stderr"] == pytest.approx(1e-3)


def test_a_log_marker_the_robot_does_not_name_is_left_out_not_a_crash(finger):
    """A user trial renamed a marker in the mocap file: STAC ignored it with a warning, but the
    diagnosis failed with an internal IndexError (its residuals took the log's markers)."""
    log = _log(finger, 3, duration=5.0)
    st = log.stream("markers")
    names = list(st.names)
    names[1] += "_renamed"
    log = log.with_streams(markers=Stream(tuple(names), st.data))
    d = diagnose(log, finger, DiagnoseOptions(domain="kinematics", max_rounds=1))
    tested = set(d.units[0].show)
    assert st.names[0] in tested and names[1] not in tested and st.names[1] not in tested
