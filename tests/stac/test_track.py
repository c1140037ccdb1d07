"""Tracking q with the calibration fixed stops once every frame has converged: LM steps keep being
accepted long after that (the cost falls by rounding), so a stop on λ alone ran every step."""

import numpy as np
import synth

import diegocal.stac.track as tracking
from diegocal.stac.calibration import Calibration
from diegocal.stac.inplace import q_step_in_place
from diegocal.stac.model import Observation
from diegocal.stac.qphase import Noise, q_step
from diegocal.stac.track import track


def _case(robot):
    """A 40-frame log, its Observation, the true calibration's Params and a noise model."""
    log = synth.simulate(robot, 40, seed=5, occlusion=0.3)
    obs = Observation(log, robot)
    return log, obs, obs.params_from(Calibration.from_dict(log.truth.params)), Noise(np.full(obs.n_pots, 0.01), 0.002)


def _cost(obs, params, noise, q):
    lam = np.full(obs.n_frames, 1e7)  # a step this damped barely moves: its cost at q is returned
    return q_step(obs, params, noise, q, lam, want_red=False)[3]


def test_tracking_stops_when_every_frame_has_converged(tree_robot, monkeypatch):
    log, obs, params, noise = _case(tree_robot)
    q0 = log.truth.signals["q"].data + np.random.default_rng(4).normal(0.0, 0.2, (obs.n_frames, tree_robot.n_joints))
    q0 = np.clip(q0, obs.lower, obs.upper)

    steps = []
    monkeypatch.setattr(tracking, "q_step_in_place", lambda *a, **k: steps.append(1) or q_step_in_place(*a, **k))
    q_stop, _ = track(obs, params, noise, q0, max_steps=40, batch=7)
    monkeypatch.undo()
    assert 2 < len(steps) < 40

    q_all, lam = q0, np.full(obs.n_frames, 1e-2)
    for _ in range(40):  # every step, as the λ-only stop ran them
        q_all, lam = q_step(obs, params, noise, q_all, lam, batch=7, want_red=False)[:2]
    stop, full = _cost(obs, params, noise, q_stop), _cost(obs, params, noise, q_all)
    np.testing.assert_allclose(stop, full, rtol=1e-7)
    start = _cost(obs, params, noise, q0)
    assert np.all(stop < start)  # the frames were far from converged at q0


def test_tracking_from_a_converged_q_stops_at_once(tree_robot, monkeypatch):
    """From a fit's own q (a diagnosis scores its fit from there) the steps fail by rounding: a
    failed step that would have raised the cost by at most the tolerance says the frame is done,
    instead of λ rising x4 per failure until it reads as stuck (eleven steps on diego)."""
    log, obs, params, noise = _case(tree_robot)
    q0 = np.clip(log.truth.signals["q"].data + 0.1, obs.lower, obs.upper)
    q_fit, _ = track(obs, params, noise, q0, max_steps=40, batch=7)

    steps = []
    monkeypatch.setattr(tracking, "q_step_in_place", lambda *a, **k: steps.append(1) or q_step_in_place(*a, **k))
    q_again, _ = track(obs, params, noise, q_fit, max_steps=40, batch=7)
    monkeypatch.undo()
    assert len(steps) <= 2
    np.testing.assert_allclose(_cost(obs, params, noise, q_again), _cost(obs, params, noise, q_fit), rtol=1e-7)


def test_tracking_says_how_far_it_is_with_the_most_time_left(tree_robot, monkeypatch):
    """``progress`` is told, step by step (here every step: the report interval set to 0), how many
    frames are tracked and the most time left (every step takes about as long, and there are at
    most ``max_steps``); the same q with or without it."""
    from diegocal.progress import Eta

    log, obs, params, noise = _case(tree_robot)
    q0 = np.clip(log.truth.signals["q"].data + 0.2, obs.lower, obs.upper)
    quiet, _ = track(obs, params, noise, q0, max_steps=40, batch=7)
    monkeypatch.setattr(tracking, "Eta", lambda total: Eta(total, every=0.0))
    lines = []
    told, _ = track(obs, params, noise, q0, max_steps=40, batch=7, progress=lines.append)
    np.testing.assert_array_equal(told, quiet)
    assert lines and lines[0].startswith("tracking q: step 1, ") and "at most" in lines[-1], lines
    counts = [int(line.split(", ")[1].split("/")[0].replace(",", "")) for line in lines]
    assert counts == sorted(counts) and counts[-1] < obs.n_frames  # the last step's line is not written


def test_tracked_frames_are_left_where_they_are(tree_robot, monkeypatch):
    """Once at most half the frames are left, the steps are taken on those alone; the State
    returned is the one at the returned q on every frame (the stepped ones written back)."""
    log, obs, params, noise = _case(tree_robot)
    q0 = np.clip(log.truth.signals["q"].data + 0.2, obs.lower, obs.upper)
    frames = []
    step = q_step_in_place
    monkeypatch.setattr(tracking, "q_step_in_place", lambda *a, **k: frames.append(a[0].n_frames) or step(*a, **k))
    q, st = track(obs, params, noise, q0, max_steps=40, batch=7)
    monkeypatch.undo()
    assert frames[0] == obs.n_frames and min(frames) <= obs.n_frames // 2, frames
    assert frames == sorted(frames, reverse=True)  # the tracked frames stay tracked
    at = obs.state(q)
    for k in ("s", "Rl", "pl"):
        np.testing.assert_allclose(getattr(st, k), getattr(at, k), rtol=0, atol=1e-12)
    monkeypatch.setattr(tracking, "TRACK_SUBSET", 0.0)  # every step on every frame
    q_every, _ = track(obs, params, noise, q0, max_steps=40, batch=7)
    np.testing.assert_allclose(_cost(obs, params, noise, q), _cost(obs, params, noise, q_every), rtol=1e-7)


def test_a_long_log_is_tracked_in_parts(tree_robot, monkeypatch):
    """``predict`` tracks TRACK_FRAMES frames at a time (a long log's forward kinematics is held
    for one part only): q and the readings predicted from the others are those of tracking the log
    whole, to the tracking's tolerance, and progress names the part."""
    import importlib

    from diegocal.progress import Eta

    predict_mod = importlib.import_module("diegocal.stac.predict")  # the package exports its function

    log, obs, params, noise = _case(tree_robot)
    cal = Calibration.from_dict(log.truth.params)
    whole = predict_mod.predict(log, tree_robot, cal, ("others",))
    sizes, lines = [], []
    monkeypatch.setattr(predict_mod, "TRACK_FRAMES", 15)
    monkeypatch.setattr(tracking, "Eta", lambda total: Eta(total, every=0.0))
    step = q_step_in_place
    monkeypatch.setattr(tracking, "q_step_in_place", lambda *a, **k: sizes.append(a[0].n_frames) or step(*a, **k))
    parts = predict_mod.predict(log, tree_robot, cal, ("others",), progress=lines.append)
    again = predict_mod.predict(log, tree_robot, cal, ("others",), q_init=whole.q)  # each part from its own q
    monkeypatch.undo()
    assert max(sizes) == 15 and obs.n_frames == 40, sizes
    assert lines[0].startswith("part 1 of 3: tracking q: step 1, ")
    assert any(x.startswith("part 3 of 3: ") for x in lines)
    np.testing.assert_allclose(parts.q, whole.q, rtol=0, atol=1e-6)
    np.testing.assert_allclose(again.q, whole.q, rtol=0, atol=1e-6)
    np.testing.assert_allclose(parts.markers, whole.markers, rtol=0, atol=1e-7)
    np.testing.assert_allclose(parts.pots, whole.pots, rtol=0, atol=1e-7)


def test_tracking_in_blocks_takes_the_steps_of_tracking_whole(tree_robot):
    """:func:`track_in_blocks` holds one block's State at a time and ends at ``track``'s q, to the
    bit; tracking each block on its own does not (its frames turn to the untracked ones alone at
    another step: a tracked frame's later steps still move it by rounding)."""
    from diegocal.stac.track import track_in_blocks

    log, obs, params, noise = _case(tree_robot)
    q0 = log.truth.signals["q"].data + np.random.default_rng(4).normal(0.0, 0.2, (obs.n_frames, tree_robot.n_joints))
    q0 = np.clip(q0, obs.lower, obs.upper)
    whole, _ = track(obs, params, noise, q0.copy(), max_steps=40, batch=7)
    alone = np.concatenate(
        [track(obs.subset(slice(i, i + 9)), params, noise, q0[i : i + 9].copy(), 40, 7)[0] for i in range(0, 40, 9)]
    )
    assert not np.array_equal(alone, whole)
    for block in (9, 16, 40):
        np.testing.assert_array_equal(track_in_blocks(obs, params, noise, q0.copy(), 40, block, 7), whole)


def test_predict_tracks_a_part_in_blocks_to_the_bit(tree_robot, monkeypatch):
    """``predict`` tracks a part of more than TRACK_BLOCK frames block by block (one block's State
    held): the same q and predicted readings, to the bit, from the pots or from a given q."""
    import importlib

    predict_mod = importlib.import_module("diegocal.stac.predict")  # the package exports its function
    log, obs, _, _ = _case(tree_robot)
    cal = Calibration.from_dict(log.truth.params)
    both = ("pots", "markers")
    whole = predict_mod.predict(log, tree_robot, cal, both, both)
    warm = predict_mod.predict(log, tree_robot, cal, both, both, q_init=whole.q + 0.05)
    blocks = []
    step = tracking._until_tracked
    monkeypatch.setattr(predict_mod, "TRACK_BLOCK", 9)
    monkeypatch.setattr(tracking, "_until_tracked", lambda o, *a: blocks.append(o.n_frames) or step(o, *a))
    cold = predict_mod.predict(log, tree_robot, cal, both, both)
    again = predict_mod.predict(log, tree_robot, cal, both, both, q_init=whole.q + 0.05)
    monkeypatch.undo()
    assert blocks == [9, 9, 9, 9, 4] * 2
    for a, b in ((whole, cold), (warm, again)):
        for name in ("q", "pots", "markers"):
            np.testing.assert_array_equal(getattr(b, name), getattr(a, name))
