"""STAC: simultaneous tracking and calibration by alternating descent (thesis §2.2.3, eq. 2.6).

The negative log-likelihood of pots and markers (eq. 2.5, 2.8-2.9, with one noise level per
sensor type, §2.3.5)

.. math:: LL(q_{1:T}, θ, σ) = \\sum_g \\Big[\\sum_{i \\in g} ρ(r_i / σ_g) + N_g \\log σ_g\\Big]

(ρ: z²/2, or for the markers a robust loss, :mod:`.robust`) is minimised by alternating a p-phase
(θ in closed form at fixed q, :mod:`.pphase`), a q-phase (per-frame damped Gauss-Newton on
eq. 2.21 at fixed θ, :mod:`.qphase`) and the dynamic
variance adjustment σ_g = RMS residual of sensor type g. Each block is a descent step, so the
cost recorded per iteration is non-increasing (up to the robust weights of Huber's loss).
σ is re-estimated (with the q-phase's degrees of freedom, see :func:`.qphase.group_sigma`; a
type the data do not resolve is held at its detection limit, :func:`.robust.floor_factor`, and
listed in the calibration's ``sigma_unresolved``) in every iteration after (q, θ) have settled
for it (SIGMA_SETTLE); that fixed-point iteration converges linearly, so every third estimate
is extrapolated by Aitken's Δ² (:func:`_aitken`).
The alternation has converged when the (q, θ) step moves the cost by less than 10 x
``tolerance`` per reading and σ by less than SIGMA_TOL; it runs until then, ``max_iterations``
(:data:`~diegocal.stac.result.MAX_ITERATIONS` by default) being only a safety cap: a fit that
reaches it is returned with ``converged`` False.

Schedule (thesis §2.6.1, Fig. 2.6). ``lm-iter`` (one LM step per alternation), ``lm-batch``
(LM to convergence, then θ) and ``bfgs`` (L-BFGS-B on all q at fixed θ, σ) are available as in
the thesis, plus, by default, a joint Gauss-Newton step on (q, θ) by the Schur complement
(:mod:`.joint_step`) tried before each LM-iter step, Marquardt-damped after a step that failed
to lower the cost (JOINT_DAMPING). Evidence (bench/bench_stac.py, bundled
finger, 200 well-spread frames, seeds from sensors.yaml, markers at link origins; mean relative
error of gains and gauge-free marker positions): after 60 iterations plain LM-batch, LM-iter
and BFGS stood at 0.028, 0.029 and 0.042 (cost -24123, -24119, -23952), still creeping, while
LM-iter + Schur converged in 20 iterations to 0.006 (cost -24246). Plain alternation stalls
along directions where θ and q co-move (a pot more precise than the markers about its joint),
which the joint step removes; per iteration LM-iter is the cheapest of the plain schedules,
LM-batch the dearest (its extra q-steps buy nothing, as the thesis observed). The thesis found
BFGS best per iteration on its hand; here it was not (3 L-BFGS iterations per alternation).
Hence the default: ``lm-iter`` with the joint step.

Thesis scale (coarse to fine). With more frames than ``coarse_frames`` the alternation first
runs on every k-th frame (about ``coarse_frames`` of them), from the initialisation below, until
σ moves by less than 1 % (COARSE_SIGMA_TOL); its q is interpolated to all frames, its LM damping
carried over, and the alternation continues on all frames, re-estimating σ from the first
iteration, to the convergence test above. The coarse stage does the many early iterations
cheaply; the full-data iterations only have to remove the subsample's sampling error (about one
standard error), which the joint step does in one or two iterations with the damping carried
over (restarted at 1e-2 it took seven, at 5,000 frames), and settle σ. Diego, 25,000 frames (bench/bench_stac.py): 11
iterations on 2,500 frames, then 4 on all. The answer is the full-data optimum: calibrated with
all frames throughout instead, the same logs end 0.007 standard errors apart in the gains, 0.004
in the biases, 0.035 in the marker positions, σ within 0.3 % (5,000 frames, part 3 of the
bench); run to tolerance 1e-10 (25,000 frames) both routes agree to 0.006 standard errors, and
the default tolerance ends 0.04 standard errors from that optimum (the previous all-frames
schedule: 0.07).

Initialisation: q from the nominal pots (rotary/encoder pots inverted, clipped to the limits;
gimbal and tendon joints by a few LM steps on the pots alone), markers at their link origins
(§2.7.1), R = I; the first p-phase then places the mocap frame by Procrustes. σ starts at each
sensor type's dynamic range (§2.3.5).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np
from threadpoolctl import threadpool_limits

from diegocal.errors import FitError, NumericalError
from diegocal.io import Log
from diegocal.robot import Robot
from diegocal.stac import robust
from diegocal.stac.calibration import FitInfo, unresolved
from diegocal.stac.covariance import covariance, theta_labels
from diegocal.stac.inplace import q_step_in_place, relinearise
from diegocal.stac.joint_step import theta_step
from diegocal.stac.model import MARKERS, Observation, Params, State
from diegocal.stac.poses import write_off_foreign_poses
from diegocal.stac.pphase import CHUNK, p_phase
from diegocal.stac.qphase import (
    Noise,
    group_rss,
    group_sigma,
    irls_weight,
    kinematics_batch,
    pot_sigmas,
    residuals,
    resolvable,
    rho,
)
from diegocal.stac.result import IterationRecord, StacOptions, StacResult, WarmStart
from diegocal.stac.robust import LOSSES, REDESCENDING
from diegocal.stac.schedules import Anderson, BfgsSchedule
from diegocal.stac.static import static_poses

SCHEDULES = ("lm-iter", "lm-batch", "bfgs")
#: σ is re-estimated only once the cost at fixed σ moves by less than this (relative). Updating
#: it every iteration while θ is still far off lets the per-type σ of the pots chase the pot
#: residuals to zero (the likelihood is unbounded there: one pot per joint can be fitted exactly),
#: a collapse seen on the test robots; waiting for (q, θ) to settle avoids it.
SIGMA_SETTLE = 1e-3
#: ... and the alternation has converged once a re-estimate moves every σ by less than this
#: (relative): σ's own standard error at thesis size is about 0.2 %, and the parameters move by
#: about 0.01 of their standard errors per 1 % of σ (bench/bench_stac.py, diego).
SIGMA_TOL = 1e-3
#: First Marquardt damping (relative to the reduced matrix's diagonal) of the joint step after a
#: full step failed to lower the cost; x 10 per further failure, ÷ 10 per success (to 0). An
#: undamped step that overshoots is otherwise rejected in every iteration while the plain
#: alternation crawls along the valley it would have crossed (seen on the finger: a pot gain far
#: off for a hundred iterations, settled within a few once a step was accepted).
JOINT_DAMPING = 1e-2
#: The coarse stage stops at a looser σ tolerance: the full-data iterations re-estimate σ anyway,
#: and the subset's σ differs from the full data's by its own sampling error (about 0.5 %).
COARSE_SIGMA_TOL = 1e-2


def check_options(options: StacOptions) -> None:
    if options.loss not in LOSSES:
        raise FitError(f"unknown loss {options.loss!r} (expected one of {', '.join(LOSSES)})")
    if options.schedule not in SCHEDULES:
        raise FitError(f"unknown schedule {options.schedule!r} (expected one of {', '.join(SCHEDULES)})")
    if options.marker_seed not in ("origin", "nominal"):
        raise FitError(f"unknown marker seed {options.marker_seed!r} (expected origin or nominal)")
    if options.max_iterations < 1:
        raise FitError("max_iterations must be at least 1")
    if options.coarse_frames < 0 or options.batch_size < 1:
        raise FitError("coarse_frames must be >= 0 (0: no coarse stage) and batch_size >= 1")


def initial_q(obs: Observation, params: Params, options: StacOptions, use: np.ndarray | None = None) -> np.ndarray:
    """q (T, n) from the pots: invert rotary/encoder pots; LM on the pots for the rest, up to ten
    steps, until a step lowers their summed cost by less than 1 % (a starting point: the
    alternation refines q with the markers).

    ``use`` (P,) bool restricts the pots used (default: all).
    """
    robot = obs.robot
    use = np.ones(obs.n_pots, dtype=bool) if use is None else use
    q = np.tile(robot.neutral(), (obs.n_frames, 1))
    direct = [j for j, p in enumerate(obs.pot_specs) if p.kind in ("rotary", "encoder") and use[j]]
    for j in direct:
        col = robot.joint_index(obs.pot_specs[j].joint)
        q[:, col] = np.clip((obs.pots[:, j] - params.bias[j]) / params.gain[j], obs.lower[col], obs.upper[col])
    if len(direct) < use.sum():
        scale = np.where(use, np.maximum(np.std(obs.pots, axis=0), 1e-6), np.inf)
        noise = Noise(scale, 1.0, use_markers=False)
        lam = np.full(obs.n_frames, 1e-2)
        prev, st = np.inf, obs.state(q, kinematics_batch(options.batch_size), keep=True)
        for _ in range(10):  # the steps written over one State (inplace.py)
            q, lam, st, cost, _ = q_step_in_place(
                obs, params, noise, q, lam, st, options.batch_size, options.jobs, False
            )
            if cost.sum() > 0.99 * prev:
                break
            prev = cost.sum()
    return q


def dynamic_range(obs: Observation) -> dict:
    """Initial σ per sensor type (§2.3.5): the typical spread of its readings."""
    out = {}
    for g in obs.groups:
        if g == MARKERS:
            out[g] = float(np.nanmean(np.nanstd(obs.markers, axis=0)))
        else:
            out[g] = float(np.mean(np.std(obs.pots[:, obs.kinds == g], axis=0)))
        out[g] = max(out[g], 1e-6)
    return out


def weights(obs: Observation, params: Params, st: State, noise: Noise):
    """Robust weights for the p-phase: pots (T, P) (all 1: Gaussian; a read-only view, no array
    of ones per call), markers (T, M); zero where occluded."""
    wp = np.broadcast_to(1.0, obs.pots.shape)
    wx = obs.valid.astype(float)
    if noise.loss != "linear":
        _, zx, _ = residuals(obs, params, noise, st.s, st.Rl, st.pl, obs.pots, obs.markers, obs.valid)
        wx = irls_weight(zx, noise.loss, noise.huber) * obs.valid
    return wp, wx


def total_cost(
    obs: Observation, params: Params, st: State, noise: Noise, sigma: dict, rss: dict | None = None
) -> float:
    """LL of eq. 2.5/2.8 with per-type σ (constants dropped). Under the linear loss it is
    Σ_g RSS_g / 2σ_g² + N_g log σ_g, from ``rss`` (:func:`.qphase.group_rss` at θ and ``st``, which
    σ's re-estimate needs too; computed when not given); under a robust one the residuals a
    chunk of frames at a time (CHUNK: their temporaries stay small on long logs)."""
    if noise.loss == "linear":
        rss = group_rss(obs, params, st) if rss is None else rss
        return float(sum(ss / (2.0 * sigma[g] ** 2) + n * np.log(sigma[g]) for g, (ss, n) in rss.items()))
    c = 0.0
    for i in range(0, obs.n_frames, CHUNK):
        sl = slice(i, i + CHUNK)
        valid = obs.valid[sl]
        zp, zx, _ = residuals(obs, params, noise, st.s[sl], st.Rl[sl], st.pl[sl], obs.pots[sl], obs.markers[sl], valid)
        for g in sigma:
            if g == MARKERS:
                c += rho(zx[valid], noise.loss, noise.huber).sum()
            else:
                z = zp[:, obs.kinds == g]
                c += 0.5 * (z * z).sum()
    for g, sg in sigma.items():
        n = 3 * obs.valid.sum() if g == MARKERS else obs.n_frames * np.sum(obs.kinds == g)
        c += n * np.log(sg)
    return float(c)


def _noise(obs, sigma, options) -> Noise:
    return Noise(pot_sigmas(obs, sigma), sigma.get(MARKERS, 1.0), options.loss, options.huber_scale)


def _update_sigma(obs, params, st, used, loss: str = "linear", sigma: dict | None = None, rss=None) -> dict:
    """§2.3.5: re-estimate σ per type from the residuals, with the q-phase's degrees of freedom;
    under a robust loss from residuals clipped at a few current σ (:func:`.robust.group_sigma`).
    A group the data do not resolve is held at its detection limit (:func:`.robust.floor_factor`)."""
    new = (
        group_sigma(obs, params, st, used, rss)
        if loss == "linear"
        else robust.group_sigma(obs, params, st, used, sigma)
    )
    return {g: max(v, 1e-9) for g, v in new.items()}


def _aitken(history: list) -> dict:
    """Aitken's Δ² extrapolation of the σ fixed-point iteration from its last three iterates.

    σ ← RSS(σ) / (N − used(σ)) converges linearly, at a rate near 0.7 for the linear pots of
    diego (their σ decides how much the gimbal angles follow them rather than the markers), so
    each type's log σ is extrapolated along its geometric tail: with steps d1, d2 and rate
    r = d2 / d1, log σ + d2 r / (1 − r). The types' iterations are coupled, so the estimated
    rate is capped at 0.75 (at most three more steps of the same size); types whose steps do
    not shrink monotonically keep their last iterate. Returns the σ to continue from and clears
    ``history``.
    """
    a, b, c = history
    out = {}
    for g, sc in c.items():
        d1, d2 = np.log(b[g] / a[g]), np.log(sc / b[g])
        r = min(d2 / d1, 0.75) if d1 != 0.0 else 0.0
        out[g] = float(sc * np.exp(d2 * r / (1.0 - r))) if 0.0 < r < 1.0 and abs(d2) < abs(d1) else sc
    history.clear()
    history.append(out)
    return out


def calibrate(log: Log, robot: Robot, options: StacOptions | None = None, start: WarmStart | None = None) -> StacResult:
    """STAC (thesis §2.2-2.3): calibrate pots, markers and the mocap frame; track q.

    Parameters
    ----------
    log : Log with ``pots`` (T, P) V and ``markers`` (T, M, 3) m (NaN where occluded)
    robot : Robot; names in the log must be in its sensors.yaml
    options : StacOptions (schedule, loss, max_iterations, tolerance, jobs, batch_size, ...)
    start : WarmStart, optional: the alternation starts there (under the linear loss, with a σ for
        every sensor type of the log) instead of from the nominal θ through the coarse stage

    Returns
    -------
    StacResult with the Calibration (values, standard errors, σ per type, cost history) and
    q (T, n) rad, the tracked joint angles.
    """
    options = options or StacOptions()
    check_options(options)
    # one BLAS thread: the products are small and many (one set per batch of frames), and BLAS
    # threads only add synchronisation (diego, 25,000 frames, loaded 2-core machine: 42 s of CPU
    # instead of 15); --jobs runs batches in parallel instead
    with threadpool_limits(limits=1, user_api="blas"):
        return _calibrate(log, robot, options, start)


def _calibrate(log: Log, robot: Robot, options: StacOptions, start: WarmStart | None = None) -> StacResult:
    t0 = time.perf_counter()
    base = Observation(log, robot)
    base.check_observable()
    history: list[IterationRecord] = []

    def refit(obs: Observation):
        return _robust_fit(obs, options, t0, history)

    warm = _warm(base, start, options, t0, history)
    obs, fine = (base, warm) if warm is not None else refit(base)
    poses = static_poses(log) if options.check_poses else None
    if poses is not None:  # static poses filed with another pose's markers (poses.py)
        obs, fine = write_off_foreign_poses(base, obs, fine, poses, refit, options)
    params, sigma, q = fine.params, fine.sigma, fine.q
    # standard errors with q marginalised (the Schur complement of eq. 2.21), not the p-phase's
    # conditional-on-q ones, which ignore the joint-angle uncertainty; cluster-robust over blocks
    # of frames (covariance.py: the residuals are correlated in time)
    cov = covariance(obs, params, _noise(obs, sigma, options), q, options.batch_size, st=fine.state)
    fit = FitInfo(history[-1].cost, len(history), fine.converged, time.perf_counter() - t0)
    cal = obs.to_calibration(params, cov.se(), sigma, "stac", fit)
    block_s = float(np.median(np.diff(log.time))) * obs.n_frames / cov.blocks if obs.n_frames > 1 else 0.0
    cal = replace(
        _with_history(cal, history),
        sigma_unresolved=unresolved(fine.unresolved),
        correlations=tuple(cov.correlations(theta_labels(obs))),
        stderr={"method": "block_sandwich", "blocks": int(cov.blocks), "block_s": round(block_s, 3)},
    )
    return StacResult(cal, q, tuple(history))


def _warm(obs: Observation, start: WarmStart | None, options: StacOptions, t0: float, history: list) -> _Stage | None:
    """The alternation from a warm start (σ re-estimated from its first iteration on); None where
    none fits: another loss than the linear, q not of every frame, a sensor type without its σ."""
    if start is None or options.loss != "linear" or np.shape(start.q) != (obs.n_frames, obs.robot.n_joints):
        return None
    sigma = {g: float(start.calibration.sigma_by_group.get(g, np.nan)) for g in obs.groups}
    if not np.all(np.isfinite(list(sigma.values()))):
        return None
    q = np.clip(np.asarray(start.q, float), obs.lower, obs.upper)
    return _alternate(obs, obs.params_from(start.calibration), q, sigma, options, t0, history)


#: Passes of "write off the markers of gross frames and fit again" (robust losses only).
MAX_REJECTIONS = 3


def _robust_fit(obs: Observation, options: StacOptions, t0: float, history: list) -> tuple[Observation, _Stage]:
    """The fit under ``options.loss`` from the nominal θ; returns it with its Observation (under a
    robust loss, with the markers of gross frames written off)."""
    if options.loss == "linear":
        return obs, _fit(obs, obs.nominal(options.marker_seed), options, t0, history)
    # the convex (Huber) fit first; frames filed with markers not their own have their markers
    # written off and the fit is redone (robust.py); then a redescending loss from there
    huber = replace(options, loss="huber")
    for _ in range(MAX_REJECTIONS):
        fine = _fit(obs, obs.nominal(options.marker_seed), huber, t0, history)
        gross = robust.gross_frames(obs, fine.params, obs.state(fine.q, kinematics_batch(options.batch_size)))
        if not gross.any():
            break
        obs = obs.without_markers(gross)
    if options.loss != "huber":
        stage = _alternate(obs, fine.params, fine.q, fine.sigma, options, t0, history, fine.lam)
        fine = replace(stage, unresolved=fine.unresolved)  # σ stays the Huber stage's
    return obs, fine


def _fit(obs: Observation, params: Params, options: StacOptions, t0: float, history: list) -> _Stage:
    """The STAC schedule from θ: a coarse stage on a subset of the frames (module docstring), then
    the alternation on all frames (``options.loss`` is linear or Huber's here)."""
    robot = obs.robot
    stride = -(-obs.n_frames // options.coarse_frames) if options.coarse_frames else 1
    # a redescending loss is not convex: its first stage (the coarse one, or a full one) uses Huber's
    first = replace(options, loss="huber") if options.loss in REDESCENDING else options
    if stride > 1:  # coarse stage: θ and σ on every stride-th frame (module docstring)
        sub = obs.subset(slice(None, None, stride))
        q = initial_q(sub, params, options)
        coarse = _alternate(sub, params, q, None, first, t0, history, sigma_tol=COARSE_SIGMA_TOL)
        params, sigma = coarse.params, coarse.sigma
        lam = np.repeat(coarse.lam, stride)[: obs.n_frames]  # warm LM state (see _alternate)
        frames = np.arange(0, obs.n_frames, stride)
        t = np.arange(obs.n_frames)
        q = np.stack([np.interp(t, frames, coarse.q[:, j]) for j in range(robot.n_joints)], axis=1)
    else:
        q, sigma, lam = initial_q(obs, params, options), None, None
        if first is not options:
            warm = _alternate(obs, params, q, sigma, first, t0, history, lam)
            params, sigma, q, lam = warm.params, warm.sigma, warm.q, warm.lam
    return _alternate(obs, params, q, sigma, options, t0, history, lam)


@dataclass(frozen=True)
class _Stage:
    """Where one run of the alternation ended: θ, its p-phase SEs (conditional on q), the joint
    step's SEs (q marginalised; None without joint steps), σ per type, q (T, n), LM damping (T,),
    the groups whose σ the last re-estimate held at its detection limit, the State at q (the
    markers' link poses and pot transmissions are functions of q alone, so it serves any
    Observation of the same frames: the covariance linearises from it)."""

    params: Params
    se: dict
    se_joint: dict | None
    sigma: dict
    q: np.ndarray
    lam: np.ndarray
    converged: bool
    unresolved: tuple = ()
    state: State | None = None


def _alternate(
    obs: Observation,
    params: Params,
    q: np.ndarray,
    sigma: dict | None,
    options: StacOptions,
    t0: float,
    history: list,
    lam: np.ndarray | None = None,
    sigma_tol: float = SIGMA_TOL,
) -> _Stage:
    """The alternation of eq. 2.6 from q (T, n) and θ; appends one IterationRecord per
    iteration to ``history``. A fresh start (``sigma`` None) takes σ from the readings' spread
    and places θ by a first p-phase; a warm start (σ given, θ converged on a subset of the
    frames) may re-estimate σ from its first iteration on."""
    # the q-phase linearises from it
    st = obs.state(q, kinematics_batch(options.batch_size), keep=options.schedule != "bfgs")
    warm = sigma is not None
    if not warm:
        sigma = dynamic_range(obs)
        noise = _noise(obs, sigma, options)
        params = p_phase(obs, st, params, *weights(obs, params, st, noise)).params
    noise = _noise(obs, sigma, options)
    se_joint = None
    converged, prev_fixed, sigma_change = False, np.inf, np.inf
    resolved = {g: True for g in obs.groups}
    sigmas: list[dict] = []
    n_obs = obs.pots.size + 3 * int(obs.valid.sum())
    lam = np.full(obs.n_frames, 1e-2) if lam is None else lam
    bfgs = BfgsSchedule(obs, options) if options.schedule == "bfgs" else None
    accel = Anderson(options.anderson) if options.anderson and bfgs is None else None
    cost = total_cost(obs, params, st, noise, sigma)
    mu = 0.0  # Marquardt damping of the joint step (JOINT_DAMPING)
    for _ in range(options.max_iterations):  # one State of every frame, its q-steps in place (inplace.py)
        noise = _noise(obs, sigma, options)
        red = warm or np.isfinite(prev_fixed)  # the q-phase's degrees of freedom, for σ below
        stepped = False
        if options.joint and bfgs is None and obs.n_pots:
            params_j, _, se_joint = theta_step(
                obs, params, noise, q, lam, options.batch_size, jobs=options.jobs, damping=mu, st=st
            )
            q_j, lam_j, st, _, used = q_step_in_place(
                obs, params_j, noise, q, lam, st, options.batch_size, options.jobs, red
            )
            try:
                ph_j = p_phase(obs, st, params, *weights(obs, params, st, noise))
                rss_j = _rss(obs, ph_j.params, st, options)
                cost_j = total_cost(obs, ph_j.params, st, noise, sigma, rss_j)
            except NumericalError:  # a step so far off that a redescending loss drops every marker
                cost_j = np.inf
            if cost_j < cost:
                q, lam, ph, cost, rss, stepped = q_j, lam_j, ph_j, cost_j, rss_j, True
                mu = mu / 10 if mu > JOINT_DAMPING / 10 else 0.0
            else:  # the full step overshot: damp the next one (and alternate plainly this time)
                st = relinearise(obs, q, st, options.batch_size, options.jobs)  # the State at q again
                mu = max(10 * mu, JOINT_DAMPING)
            q_j = None
        if not stepped:
            q_old = q
            if bfgs is not None:
                q, st, used = bfgs.step(q, params, noise)
            else:
                steps = options.q_steps if options.schedule == "lm-iter" else 30
                for _ in range(steps):
                    q, lam, st, _, used = q_step_in_place(
                        obs, params, noise, q, lam, st, options.batch_size, options.jobs, red
                    )
                    if options.schedule == "lm-batch" and np.all(lam >= 1e3):
                        break
            ph = p_phase(obs, st, params, *weights(obs, params, st, noise))
            rss = _rss(obs, ph.params, st, options)
            cost = total_cost(obs, ph.params, st, noise, sigma, rss)
            if accel is not None:  # Anderson extrapolation of the (q -> q-phase(p-phase(q))) fixed point
                q_mix = accel.mix(q_old, q)
                if q_mix is not None:
                    q_mix = np.clip(q_mix, obs.lower, obs.upper)
                    st_mix = obs.state(q_mix, kinematics_batch(options.batch_size))
                    ph_mix = p_phase(obs, st_mix, params, *weights(obs, params, st_mix, noise))
                    rss_mix = _rss(obs, ph_mix.params, st_mix, options)
                    cost_mix = total_cost(obs, ph_mix.params, st_mix, noise, sigma, rss_mix)
                    if cost_mix < cost:
                        q, st, ph, cost, rss = q_mix, st_mix, ph_mix, cost_mix, rss_mix
                    else:
                        accel.reset()
        params = ph.params
        change = abs(prev_fixed - cost)  # what the (q, θ) step did at fixed σ
        # §2.3.5, once (q, θ) have settled (SIGMA_SETTLE); at once on a warm start
        frozen = options.loss in REDESCENDING  # σ from the Huber stage (robust.py)
        if not frozen and (change < SIGMA_SETTLE * max(abs(cost), 1.0) or (warm and not np.isfinite(prev_fixed))):
            new = _update_sigma(obs, params, st, used, options.loss, sigma, rss)
            resolved = resolvable(obs, used)
            sigmas.append(new)
            if len(sigmas) == 3:  # a group at its floor is not extrapolated past it
                new = {g: v if resolved[g] else new[g] for g, v in _aitken(sigmas).items()}
            sigma_change = max(abs(new[g] / sigma[g] - 1.0) for g in new)
            sigma = new
            cost = total_cost(obs, params, st, _noise(obs, sigma, options), sigma, rss)
        prev_fixed = cost
        if accel is not None:
            accel.reset()
        it = len(history) + 1
        history.append(
            IterationRecord(
                it,
                cost,
                _rms_pots(obs, sigma),
                sigma.get(MARKERS, np.nan),
                time.perf_counter() - t0,
                obs.n_frames,
            )
        )
        if options.on_iteration is not None:
            options.on_iteration(it, obs.to_calibration(params, ph.se, sigma, "stac"))
        # converged when the (q, θ) step moves the cost (nats) by less than 10 x tolerance per
        # reading and the last re-estimate moved σ by less than sigma_tol
        if change < 10 * options.tolerance * n_obs and (sigma_change < sigma_tol or frozen):
            converged = True
            break
    unresolved = tuple(g for g, ok in resolved.items() if not ok)
    return _Stage(params, ph.se, se_joint, sigma, q, lam, converged, unresolved, st)


def _rss(obs: Observation, params: Params, st: State, options: StacOptions) -> dict | None:
    """:func:`.qphase.group_rss` under the linear loss (the cost and σ's re-estimate share it)."""
    return group_rss(obs, params, st) if options.loss == "linear" else None


def _rms_pots(obs, sigma) -> float:
    v = [sigma[g] for g in obs.groups if g != MARKERS]
    return float(np.sqrt(np.mean(np.square(v)))) if v else float("nan")


def _with_history(cal, history):
    return replace(
        cal,
        history=tuple(
            {
                "iteration": h.iteration,
                "cost": float(h.cost),
                "sigma_pots": float(h.sigma_pots),
                "sigma_markers": float(h.sigma_markers),
                "seconds": float(h.seconds),
                "frames": int(h.frames),
            }
            for h in history
        ),
    )
