"""The q-phase's LM step written over the State it starts from (issue #33: long logs).

:func:`~diegocal.stac.qphase.q_step` writes its new :class:`~diegocal.stac.model.State` into a
second State of all T frames (a frame whose step fails takes back its row of the first), so the
alternation held two: on diego 5 kB per frame each (the joint twists ``xi`` and ∂s/∂q of the linear
pots are half of it), 180 MB apiece on the 36,000 training frames of a 10-minute diagnosis.
:func:`q_step_in_place` takes the step a unit of :data:`~diegocal.stac.qphase.KINEMATICS_BATCH`
frames at a time instead: the unit's steps are solved from its rows of the State at q (in
``batch``-frame slices, as ``q_step`` solves them), the forward kinematics runs at its candidates,
and the rows whose step lowers the cost are written over the State's before the next unit: only
one unit's new linearisation is held beside the one State. Every frame goes through the same
arithmetic, in the same slices, as in ``q_step``: the results are the same bits.

The State before the step is gone once the step is taken: where the caller still needs it (a
joint step the cost rejects, :func:`~diegocal.stac.stac._alternate`), :func:`relinearise` makes it
again at q, one pass of the forward kinematics.
"""

from __future__ import annotations

import numpy as np

from diegocal.stac.loo import frame_slices
from diegocal.stac.model import KEEP_FRAMES, Observation, Params, State
from diegocal.stac.qphase import Noise, _lm_batch, _put, frame_cost, kinematics_batch, map_batches, q_step


def q_step_in_place(
    obs: Observation,
    params: Params,
    noise: Noise,
    q: np.ndarray,
    lam: np.ndarray,
    st: State,
    batch: int = 250,
    jobs: int = 1,
    want_red: bool = True,
    trial: np.ndarray | None = None,
):
    """One LM step on every frame, as :func:`~diegocal.stac.qphase.q_step` with ``st`` (the State at
    q (T, n), its linearisation kept) overwritten by the State at the new q (module docstring).

    Returns (q (T, n), λ (T,), ``st`` (now at the new q), cost (T,), redundancy {group: Σ tr_g}
    at the old q, empty unless ``want_red``). q and λ are not changed. A State without room for the
    linearisation goes to ``q_step`` (Anderson's mix, :func:`~diegocal.stac.stac._alternate`) or,
    on more than :data:`~diegocal.stac.model.KEEP_FRAMES` frames, is stepped in place, each slice
    linearised again at q (its s and poses are those the State holds: the same numbers).
    ``trial`` (T,): filled with each frame's cost at its step's candidate, taken or not.
    """
    T = q.shape[0]
    lean = st is not None and st.xi is None and T > KEEP_FRAMES  # its steps linearise at q themselves
    if st is None or (st.xi is None and not lean):  # (Anderson's mix)
        return q_step(obs, params, noise, q, lam, batch, jobs, want_red, st, trial=trial)
    cand, c0, c1 = np.empty_like(q), np.empty(T), np.empty(T) if trial is None else trial
    unit = batch * -(-kinematics_batch(batch) // batch)  # whole slices of ``batch`` frames

    def step(sl: slice) -> list:
        # Alg. of q_step: the damped steps of the unit's slices from st's rows at q ...
        reds = [
            _lm_batch(obs, params, noise, q, lam, s, want_red, None if lean else st, cand, c0, None)
            for s in frame_slices(sl.stop - sl.start, batch)
            for s in (slice(sl.start + s.start, sl.start + s.stop),)
        ]
        # ... the forward kinematics at the candidates, then the accepted rows over st's
        lin = obs.poses_at(cand[sl]) if lean else obs.linearise(cand[sl])
        c1[sl] = frame_cost(obs, params, noise, lin.s, lin.Rl, lin.pl, obs.pots[sl], obs.markers[sl], obs.valid[sl])
        ok = c1[sl] <= c0[sl]
        if ok.all():
            _put(st, sl, lin)
        elif ok.any():
            took = np.flatnonzero(ok)
            st.put(sl.start + took, State(lin.s, lin.Rl, lin.pl, lin.xi, lin.ds_lin).take(took))
        return reds

    reds = [r for part in map_batches(step, T, unit, jobs) for r in part]
    red = {g: sum(r[g] for r in reds) for g in reds[0]}
    ok = c1 <= c0  # accept: λ/3; reject: λ x 4, keep q
    lam_out = np.where(ok, np.maximum(lam / 3.0, 1e-7), np.minimum(lam * 4.0, 1e7))
    back = np.flatnonzero(~ok)
    cand[back] = q[back]
    return cand, lam_out, st, np.where(ok, c1, c0), red


def relinearise(obs: Observation, q: np.ndarray, st: State, batch: int = 250, jobs: int = 1) -> State:
    """``st`` (a State of T frames with room for the linearisation) overwritten by the State at
    q (T, n), its linearisation kept: :meth:`~diegocal.stac.model.Observation.state` without a second
    State, the forward kinematics :func:`~diegocal.stac.qphase.kinematics_batch` frames at a time.
    A State without that room: on more than :data:`~diegocal.stac.model.KEEP_FRAMES` frames its s
    and poses overwritten, else a new State with the linearisation."""
    if st.xi is None and q.shape[0] <= KEEP_FRAMES:
        return obs.state(q, kinematics_batch(batch), keep=True)
    at = obs.linearise if st.xi is not None else obs.poses_at  # a lean State: s and poses only
    map_batches(lambda sl: _put(st, sl, at(q[sl])), q.shape[0], kinematics_batch(batch), jobs)
    return st
