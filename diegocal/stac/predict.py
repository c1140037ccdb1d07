"""Cross-sensor prediction on novel data with a fixed calibration (thesis §2.7.2, Tables 2.1-2.2).

The q-phase alone (eq. 2.21) is run on a held-out log using only the *source* sensor types;
the tracked joint angles then predict every sensor (eq. 2.11-2.20) and the mean absolute
error is reported per *target* type: markers as the mean distance (m), pots in their own unit
(V, or m for tendons). Predicting a type that was also a source gives the model's fit to the
data (the thesis prints those in parentheses). The source ``others`` predicts each reading from
every other sensor of its frame (:mod:`diegocal.stac.loo`): the held-out score ``diagnose``
gives a kinematic model.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from diegocal.errors import FitError
from diegocal.io import Log
from diegocal.robot import Robot
from diegocal.stac.calibration import Calibration
from diegocal.stac.loo import deleted_from_others, frame_slices
from diegocal.stac.model import MARKERS, Observation
from diegocal.stac.qphase import Noise, kinematics_batch
from diegocal.stac.result import StacOptions
from diegocal.stac.stac import initial_q
from diegocal.stac.terms import POT_CAUSES, apply_terms, pot_columns, to_log_markers, with_slip_markers
from diegocal.stac.track import track, track_in_blocks

#: accepted sensor-type names: the pot kinds, all pots, and the markers; as a source, ``others``:
#: each reading from all the other sensors of its frame
SENSOR_TYPES = ("markers", "pots", "rotary", "linear", "tendon", "encoder")
OTHERS = "others"
SOURCE_TYPES = (*SENSOR_TYPES, OTHERS)

#: Frames tracked at a time: q at a fixed calibration is a per-frame problem, and tracking a long
#: log in parts (its start from the pots included) keeps only one part's forward kinematics
#: (kilobytes per frame) in memory. A log of at most this many frames is tracked whole.
TRACK_FRAMES = 20_000
#: Frames whose State is held at a time within a part (:func:`~diegocal.stac.track.track_in_blocks`:
#: the same q; diego's State is 4.9 kB per frame; issue #33). A part of at most this many frames
#: is tracked whole.
TRACK_BLOCK = 2_000


@dataclass(frozen=True)
class Prediction:
    """Tracked q (T, n) rad, predicted pots (T, P) V and markers (T, M, 3) m, and the MAE table.

    mae : {type: MAE} for each target type present in the log (m for markers, sensor unit else)
    """

    q: np.ndarray
    pots: np.ndarray
    markers: np.ndarray
    pot_names: tuple[str, ...]
    marker_names: tuple[str, ...]
    sources: tuple[str, ...]
    targets: tuple[str, ...]
    mae: dict
    full_pots: np.ndarray | None = None  # the pots at q from every source (``others``: not left out)


def _groups(names, obs: Observation, what: str) -> set[str]:
    out = set()
    if what == "from" and OTHERS in names:
        if len(tuple(names)) > 1:
            raise FitError(f"--from {OTHERS} predicts each reading from all the others; give it alone")
        return set(obs.groups)
    for n in names:
        if n not in SENSOR_TYPES:
            raise FitError(f"unknown sensor type {n!r} in --{what} (expected one of {', '.join(SENSOR_TYPES)})")
        out |= set(obs.kinds) if n == "pots" else {n}
    present = set(obs.groups)
    missing = sorted(out - present)
    if missing:
        raise FitError(
            f"--{what} {', '.join(missing)}: the log has no sensors of that type (it has {', '.join(obs.groups)})"
        )
    return out


def predict(
    log: Log,
    robot: Robot,
    calibration: Calibration,
    sources=("pots",),
    targets=("markers",),
    options: StacOptions | None = None,
    max_steps: int = 40,
    q_init: np.ndarray | None = None,
    progress=None,
) -> Prediction:
    """Track q from ``sources`` with the calibration fixed; predict ``targets`` (thesis §2.7.2).

    ``q_init`` (T, n) rad: joint angles to start the tracking from (a previous fit's), instead of
    the pots' inversion. ``sources`` ``("others",)``: q is tracked from every sensor and each
    reading is predicted from the others (:mod:`diegocal.stac.loo`), NaN where they cannot.
    ``progress(text)``: told how far the tracking is (:func:`~diegocal.stac.track.track`).

    A calibration with extra terms (``calibration.terms``, found by ``diegocal diagnose``) is
    honoured through :func:`diegocal.stac.terms.apply_terms`: the model runs on the log mapped into
    its terms, and the predicted markers are mapped back to the log's markers and clock (the MAE
    table is taken in the mapped terms: faulty readings removed, markers on the pots' clock).
    """
    options = options or StacOptions()
    if calibration.terms:
        applied = apply_terms(calibration.terms, log, robot)
        cal = with_slip_markers(replace(calibration, terms=()), applied, calibration.terms)
        pred = predict(applied.log, applied.robot, cal, sources, targets, options, max_steps, q_init, progress)
        model_pots = None
        if any(t.cause in POT_CAUSES for t in calibration.terms):  # of the model's s
            model_pots = pred.full_pots
            applied = apply_terms(calibration.terms, log, robot, model_pots)
            pred = predict(applied.log, applied.robot, cal, sources, targets, options, max_steps, pred.q, progress)
        markers = to_log_markers(applied, pred.marker_names, pred.markers) if pred.marker_names else pred.markers
        pots = pots_with_terms(calibration.terms, log, pred.pot_names, pred.pots, model_pots)
        return replace(pred, pots=pots, markers=markers, marker_names=applied.marker_names)
    obs = Observation(log, robot, need=(), needed_by="predict")
    src = _groups(sources, obs, "from")
    tgt = _groups(targets, obs, "to")
    params = obs.params_from(calibration)
    sig = dict(calibration.sigma_by_group)
    for g in obs.groups:
        if not np.isfinite(sig.get(g, np.nan)):
            sig[g] = calibration.sigma_markers if g == MARKERS else calibration.sigma_pots
        if not np.isfinite(sig.get(g, np.nan)):
            sig[g] = 0.002 if g == MARKERS else 0.01  # an uncalibrated (nominal) model: typical noise
    sig_p = np.array([sig[k] if k in src else np.inf for k in obs.kinds], dtype=float)
    noise = Noise(
        sig_p,
        sig.get(MARKERS, 1.0),
        options.loss,
        options.huber_scale,
        use_pots=bool(src - {MARKERS}),
        use_markers=MARKERS in src,
    )
    use = np.isin(obs.kinds, list(src))

    def start(part: Observation, sl: slice) -> np.ndarray:  # q to track a part's frames from
        if q_init is not None:
            return np.clip(np.asarray(q_init[sl], float), part.lower, part.upper)
        if noise.use_pots:
            return initial_q(part, params, options, use=use)
        return np.tile(robot.neutral(), (part.n_frames, 1))

    q, pots, markers = _tracked(obs, params, noise, start, max_steps, options, progress)
    full_pots = pots
    if OTHERS in sources:  # each reading from the others: reading − its deleted residual
        r = np.concatenate([obs.pots - pots, (obs.markers - markers).reshape(obs.n_frames, -1)], axis=1)
        rp, rm = deleted_from_others(obs, params, sig, q, r, options.jobs)
        pots, markers = obs.pots - rp, obs.markers - rm
    mae = {}
    for g in sorted(tgt):
        if g == MARKERS:
            d = np.linalg.norm(markers - obs.markers, axis=-1)[obs.valid]
            mae[g] = float(np.nanmean(d))
        else:
            k = obs.kinds == g
            mae[g] = float(np.nanmean(np.abs(pots[:, k] - obs.pots[:, k])))
    return Prediction(
        q,
        pots,
        markers,
        obs.pot_names,
        obs.marker_names,
        tuple(sorted(src)),
        tuple(sorted(tgt)),
        mae,
        full_pots,
    )


def _tracked(obs: Observation, params, noise: Noise, start, max_steps: int, options: StacOptions, progress):
    """q tracked (:func:`~diegocal.stac.track.track`) TRACK_FRAMES at a time, each part from
    ``start(part, frames)`` (its Observation and slice: the pots' inversion steps on the part
    too), a part of more than TRACK_BLOCK frames a block at a time, and the pots (T, P) and
    markers (T, M, 3) the calibration predicts at it. Progress is told per part (and block), its
    time left the part's (block's)."""
    T = obs.n_frames
    parts = frame_slices(T, TRACK_FRAMES)
    q = np.empty((T, obs.robot.n_joints))
    pots, markers = np.empty((T, obs.n_pots)), np.empty((T, obs.n_markers, 3))
    for i, sl in enumerate(parts):
        part, told = (obs, progress) if len(parts) == 1 else (obs.subset(sl), _part_progress(progress, i, len(parts)))
        if part.n_frames <= TRACK_BLOCK:
            q[sl], st = track(part, params, noise, start(part, sl), max_steps, options.batch_size, options.jobs, told)
            pots[sl], markers[sl] = _readings(params, st)
            del st  # let this part's States go before the next part's are made
            continue
        q[sl] = track_in_blocks(
            part, params, noise, start(part, sl), max_steps, TRACK_BLOCK, options.batch_size, options.jobs, told
        )
        for b in frame_slices(part.n_frames, TRACK_BLOCK):  # the readings at q, a block at a time
            at = slice(sl.start + b.start, sl.start + b.stop)
            pots[at], markers[at] = _readings(params, obs.subset(at).state(q[at], kinematics_batch(options.batch_size)))
    return q, pots, markers


def _readings(params, st) -> tuple:
    """The pots (B, P) and markers (B, M, 3) θ predicts from a State of B frames (eq. 2.11-2.20)."""
    xb = np.einsum("tmij,mj->tmi", st.Rl, params.xyz) + st.pl
    return params.gain * st.s + params.bias, xb @ params.R.T + params.T


def _part_progress(progress, i: int, n: int):
    """``progress`` with the part of the log it is told about named first."""
    if progress is None:
        return None
    return lambda text: progress(f"part {i + 1} of {n}: {text}")


def pots_with_terms(terms, log: Log, names, pots: np.ndarray, model_pots: np.ndarray | None) -> np.ndarray:
    """Predicted pot readings (T, P) of the model's linear transfer, with each pot term's part of
    the reading added back (:func:`diegocal.stac.terms.pot_columns`, at the model readings
    ``model_pots`` the log was mapped with): the readings the sensor itself would give."""
    if model_pots is None:
        return pots
    raw = log.stream("pots")
    out = np.array(pots, float, copy=True)
    for t in terms:
        if t.cause in POT_CAUSES and t.channel in names:
            j = list(names).index(t.channel)
            out[:, j] += pot_columns(t, raw.column(t.channel), model_pots[:, j]) @ t.values
    return out
