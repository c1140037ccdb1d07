"""Two routes agree (issue #33, long logs): STAC on more than KEEP_FRAMES frames holds s and the
link poses only, its steps linearising again where they need it, and ends at the fit of the
State that keeps the linearisation, to the bit; the start from the pots steps over one State
and takes the steps of :func:`~diegocal.stac.qphase.q_step`, to the bit."""

import numpy as np
import synth

import diegocal.stac.inplace as inplace
import diegocal.stac.model as model
import diegocal.stac.qphase as qphase
import diegocal.stac.stac as stac
from diegocal.stac.result import StacOptions
from diegocal.stac.stac import calibrate, initial_q

FIELDS = ("gain", "bias", "marker_xyz", "gain_se", "bias_se", "marker_xyz_se", "mocap_R", "mocap_T")


def test_stac_without_the_kept_linearisation_is_the_same_fit(tree_robot, monkeypatch):
    log = synth.simulate(tree_robot, 300, seed=3, occlusion=0.2)
    options = StacOptions(batch_size=7, coarse_frames=150)  # a coarse stage of 150 frames, then 300
    kept = calibrate(log, tree_robot, options)
    lean = []
    step = stac.q_step_in_place
    monkeypatch.setattr(stac, "q_step_in_place", lambda *a, **k: lean.append(a[5].xi is None) or step(*a, **k))
    for mod in (model, inplace):
        monkeypatch.setattr(mod, "KEEP_FRAMES", 200)
    got = calibrate(log, tree_robot, options)
    monkeypatch.undo()
    assert any(lean) and not all(lean)  # the coarse stage kept its linearisation, the full one did not
    np.testing.assert_array_equal(got.q, kept.q)
    a, b = kept.calibration, got.calibration
    for name in FIELDS:
        np.testing.assert_array_equal(getattr(b, name), getattr(a, name))
    assert b.sigma_by_group == a.sigma_by_group
    assert [h["cost"] for h in b.history] == [h["cost"] for h in a.history]


def test_a_lean_state_is_stepped_in_place_as_q_step_steps(tree_robot, monkeypatch):
    """On more than KEEP_FRAMES frames the State holds no linearisation; the in-place step on it
    takes q_step's step (frames accepted and rejected alike), and :func:`relinearise` writes the
    State at q over it."""
    _, obs, params, noise, q0, lam = synth.q_step_start(tree_robot, 600)
    full = obs.state(q0, 25, keep=True)
    ref = qphase.q_step(obs, params, noise, q0, lam, 7, 2, True, obs.state(q0, 500, keep=True))
    for mod in (model, inplace):
        monkeypatch.setattr(mod, "KEEP_FRAMES", 500)
    lean = obs.state(q0, 25, keep=True)
    assert full.xi is not None and lean.xi is None and lean.ds_lin is None
    for name in ("s", "Rl", "pl"):
        np.testing.assert_array_equal(getattr(lean, name), getattr(full, name))
    got = inplace.q_step_in_place(obs, params, noise, q0, lam, lean, 7, 2, True)
    assert got[2] is lean and 0 < np.sum(ref[1] > lam) < obs.n_frames  # some steps rejected
    for x, y in zip((ref[0], ref[1], ref[3]), (got[0], got[1], got[3]), strict=True):
        np.testing.assert_array_equal(y, x)
    assert got[4] == ref[4]
    for name in ("s", "Rl", "pl"):
        np.testing.assert_array_equal(getattr(lean, name), getattr(ref[2], name))
    back = inplace.relinearise(obs, q0, lean, 7, 2)
    assert back is lean and back.xi is None
    for name in ("s", "Rl", "pl"):
        np.testing.assert_array_equal(getattr(back, name), getattr(full, name))


def test_the_start_from_the_pots_steps_over_one_state(tree_robot, monkeypatch):
    """:func:`initial_q` held two States of every frame (``q_step`` writing its new one beside the
    one it started from); now one, written over, with the same q."""
    log, obs, params, _, _, _ = synth.q_step_start(tree_robot, 90)
    options = StacOptions(batch_size=7)
    blanks = []
    blank = qphase._blank
    monkeypatch.setattr(qphase, "_blank", lambda *a: blanks.append(a[1]) or blank(*a))
    q = initial_q(obs, params, options)
    monkeypatch.undo()
    assert not blanks
    assert len(obs.linear)  # gimbals: the start takes LM steps on the pots
    # the loop as it was: q_step, its new State beside the old
    scale = np.maximum(np.std(obs.pots, axis=0), 1e-6)
    noise = qphase.Noise(scale, 1.0, use_markers=False)
    ref, lam, prev, st, spare = initial_q_direct(obs, params), np.full(obs.n_frames, 1e-2), np.inf, None, None
    for _ in range(10):
        ref, lam, new, cost, _ = qphase.q_step(obs, params, noise, ref, lam, 7, 1, False, st, spare)
        spare, st = st, new
        if cost.sum() > 0.99 * prev:
            break
        prev = cost.sum()
    np.testing.assert_array_equal(q, ref)


def initial_q_direct(obs, params):
    """q with the rotary and encoder pots inverted, the other joints at neutral (initial_q's start)."""
    q = np.tile(obs.robot.neutral(), (obs.n_frames, 1))
    for j, p in enumerate(obs.pot_specs):
        if p.kind in ("rotary", "encoder"):
            col = obs.robot.joint_index(p.joint)
            q[:, col] = np.clip((obs.pots[:, j] - params.bias[j]) / params.gain[j], obs.lower[col], obs.upper[col])
    return q
