"""q tracked at a fixed θ: LM steps on every frame until each has converged (thesis eq. 2.21, the
q-phase alone), what ``predict`` and the held-out scores run.

The steps are written over the one State they start from (:func:`~diegocal.stac.inplace.q_step_in_place`,
issue #33): a part of TRACK_FRAMES frames (:mod:`diegocal.stac.predict`) holds one State of its
frames, and half of one more while the last untracked frames step alone, instead of two; tracked in
blocks (:func:`track_in_blocks`), one block's.
"""

from __future__ import annotations

import numpy as np

from diegocal.progress import Eta, duration
from diegocal.stac.inplace import q_step_in_place, relinearise
from diegocal.stac.loo import frame_slices
from diegocal.stac.model import Observation, Params
from diegocal.stac.qphase import Noise, _blank

#: A frame is tracked once an accepted LM step lowers its cost by at most this share of it, or a
#: failed one would have raised it by at most this share (or its steps keep failing): the cost is
#: then within about that share of its minimum.
TRACK_TOL = 1e-8


#: Once no more than this share of the frames is left to track, the steps are taken on those
#: frames alone (the others keep their q and State): a few slow frames no longer cost a step on all.
TRACK_SUBSET = 0.5


def track(
    obs: Observation, params: Params, noise: Noise, q, max_steps: int, batch: int = 250, jobs: int = 1, progress=None
):
    """LM steps (:func:`~diegocal.stac.qphase.q_step`, in place) from q (T, n) until every frame is
    tracked (:data:`TRACK_TOL`) or ``max_steps``: (q, the State at q). A frame's steps keep being
    accepted long after it has converged (the cost still falls by rounding), so λ alone never says
    it is done; and from a converged q (a fit's) its steps fail by rounding, so λ would take many
    steps to say it. A tracked frame is left where it is (:data:`TRACK_SUBSET`).
    ``progress(text)``: told every few seconds how many frames are tracked, with the most time
    left (every step takes about as long, and there are at most ``max_steps``)."""
    T = q.shape[0]
    lam, cost = np.full(T, 1e-2), np.full(T, np.inf)
    tracked = np.zeros(T, dtype=bool)
    trial = np.empty(T)  # each step's cost at its candidate, taken or not
    st = relinearise(obs, q, _blank(obs, T), batch, jobs)  # the State at q, the steps written over it
    eta = Eta(max_steps)
    for k in range(1, max_steps + 1):
        todo = np.flatnonzero(~tracked)
        if len(todo) > TRACK_SUBSET * T:  # a step on every frame
            at = slice(None)
            q, new_lam, st, c, _ = q_step_in_place(obs, params, noise, q, lam, st, batch, jobs, False, trial)
            tried = trial
        else:  # on the untracked frames only: their rows of the State, stepped in place, put back
            at, tried, sub = todo, np.empty(len(todo)), st.take(todo)
            q_at, new_lam, sub, c, _ = q_step_in_place(
                obs.subset(todo), params, noise, q[todo], lam[todo], sub, batch, jobs, False, tried
            )
            q[todo] = q_at
            st.put(todo, sub)
        tracked[at] |= _settled(new_lam, lam[at], cost[at], c, tried)
        lam[at], cost[at] = new_lam, c
        if np.all(tracked):
            break
        if progress is not None and eta.due(k):
            left = duration(eta.left(k))
            progress(f"tracking q: step {k}, {int(tracked.sum()):,}/{tracked.size:,} frames tracked, "
                     f"{duration(eta.elapsed())} so far, at most {left} left")
    return q, st


def track_in_blocks(
    obs: Observation, params: Params, noise: Noise, q, max_steps: int, block: int, batch: int = 250, jobs: int = 1,
    progress=None,
) -> np.ndarray:
    """:func:`track`'s q (T, n), one block of ``block`` frames' State held at a time (issue #33).

    ``track`` steps every frame while more than :data:`TRACK_SUBSET` of them are untracked, the
    tracked ones too, then the untracked ones alone: a frame's q depends on when the frames tracked
    with it pass that share. A frame's own steps do not depend on the others (its kinematics and
    its step are the same numbers in any batch), so two passes over the blocks give the same q:
    each frame stepped until it is tracked, noting after which step; then, from those steps, the
    step at which the frames together would have turned to the untracked ones alone (and the one
    after which all were tracked), and each frame stepped on to there, its State made again at its
    q. ``progress`` is told in the first pass, per block."""
    T = q.shape[0]
    q, lam, at = np.array(q, float), np.full(T, 1e-2), np.full(T, max_steps + 1)
    blocks = frame_slices(T, block)
    for i, b in enumerate(blocks):
        told = None if progress is None else (lambda text, i=i: progress(f"block {i + 1} of {len(blocks)}: {text}"))
        q[b], lam[b], at[b] = _until_tracked(obs.subset(b), params, noise, q[b], max_steps, batch, jobs, told)
    untracked = np.array([np.sum(at >= k) for k in range(1, max_steps + 1)])  # at the start of step k
    switch = np.flatnonzero(untracked <= TRACK_SUBSET * T)
    first = int(switch[0]) + 1 if len(switch) else max_steps + 1  # the first step on the untracked alone
    last = min(max_steps, int(at.max()))  # every frame tracked after it (or the cap)
    more = np.minimum(last, np.maximum(first - 1, at)) - np.minimum(at, max_steps)
    for b in blocks:
        _step_on(obs.subset(b), params, noise, q[b], lam[b], more[b], batch, jobs)
    return q


def _until_tracked(obs: Observation, params: Params, noise: Noise, q, max_steps: int, batch: int, jobs: int, progress):
    """:func:`track` with every step on the untracked frames alone: (q (T, n), λ (T,), the step
    after which each frame was first tracked (T,), ``max_steps`` + 1 where never)."""
    T = q.shape[0]
    lam, cost = np.full(T, 1e-2), np.full(T, np.inf)
    at = np.full(T, max_steps + 1)
    st = relinearise(obs, q, _blank(obs, T), batch, jobs)
    eta = Eta(max_steps)
    for k in range(1, max_steps + 1):
        todo = np.flatnonzero(at > max_steps)
        tried, sub = np.empty(len(todo)), st.take(todo)
        q_at, new_lam, sub, c, _ = q_step_in_place(
            obs.subset(todo), params, noise, q[todo], lam[todo], sub, batch, jobs, False, tried
        )
        q[todo] = q_at
        st.put(todo, sub)
        at[todo[_settled(new_lam, lam[todo], cost[todo], c, tried)]] = k
        lam[todo], cost[todo] = new_lam, c
        if np.all(at <= max_steps):
            break
        if progress is not None and eta.due(k):
            progress(f"tracking q: step {k}, {int(np.sum(at <= max_steps)):,}/{T:,} frames tracked, "
                     f"{duration(eta.elapsed())} so far, at most {duration(eta.left(k))} left")
    return q, lam, at


def _settled(new_lam, lam, was, c, tried) -> np.ndarray:
    """The frames a step leaves tracked: λ at its cap, or the step, taken or only tried, lowering
    the cost by at most TRACK_TOL of it."""
    accepted = new_lam < lam
    done = np.where(accepted, np.isfinite(was) & (was - c <= TRACK_TOL * was), tried - c <= TRACK_TOL * c)
    return (new_lam >= 1e3) | done


def _step_on(obs: Observation, params: Params, noise: Noise, q, lam, more, batch: int, jobs: int) -> None:
    """Each frame's LM step taken ``more`` (T,) more times from q (T, n) and λ (T,), in place."""
    todo = np.flatnonzero(more > 0)
    if not len(todo):
        return
    sub, qs, ls, left = obs.subset(todo), q[todo], lam[todo], more[todo].copy()
    st = relinearise(sub, qs, _blank(sub, len(todo)), batch, jobs)
    while np.any(left > 0):
        live = np.flatnonzero(left > 0)
        part = st.take(live)
        q_at, ls[live], part, _, _ = q_step_in_place(
            sub.subset(live), params, noise, qs[live], ls[live], part, batch, jobs, False
        )
        qs[live] = q_at
        st.put(live, part)
        left[live] -= 1
    q[todo], lam[todo] = qs, ls
