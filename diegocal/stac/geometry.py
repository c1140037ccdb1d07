"""Full kinematic calibration from static poses: link geometry on top of STAC (issue #34).

STAC (thesis ch. 2) takes the URDF's link geometry as exact. Here each joint j that moves a
marker also gets the 6-parameter deviation of its placement, ``jointPlacement_j · SE3(exp(r_j),
d_j)`` in its own nominal frame (``joint_geometry``, :func:`diegocal.robot.model.perturb_joint_placements`),
fitted with the baseline's marker model (eq. 2.11-2.12) at the joint angles the pots give
(eq. 2.2, ``q = (p − bias) / gain``)::

    x_km = R (base_T_link(q_k; d, r) d_m) + T0,      θ = [T0, R, d_1:M, bias, gain, d_j, r_j]

Many of these parameters are redundant (a revolute joint's rotation about its own axis is its
joint zero; the first joint's placement is the mocap frame's). :func:`identifiable` keeps a
maximal set whose columns of the stacked Jacobian are independent, in priority order (the
frame and the markers, then the pots' biases and gains, then the geometry), by QR with column
pivoting of the column-normalised Jacobian within each group, after the groups before it
are projected out; a parameter whose column keeps less than ``TOL`` of its norm is dropped (held
at its start) and the combination of kept parameters it is aliased with is reported. The model
is then fitted by Gauss-Newton on the kept parameters, weighted by each pose's covariance

    C_k = (σ_m² I + s² J_q,k diag(1/gain²) J_q,kᵀ) / n_k

(marker noise σ_m, pot noise s propagated through the joint Jacobian, n_k samples averaged),
with (σ_m, s) re-estimated by maximum likelihood from the residuals and scaled so that the
whitened χ² equals its degrees of freedom; the standard errors are those of the weighted
normal equations, (JᵀC⁻¹J)⁻¹.

The poses are those of :func:`diegocal.stac.static.static_poses`, and STAC's calibration gives
the start and the poses written off as another pose's markers (:mod:`diegocal.stac.poses`).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace

import numpy as np
import pinocchio as pin
from scipy.linalg import qr
from scipy.stats import chi2

from diegocal.errors import FitError
from diegocal.io import Log
from diegocal.robot import Robot
from diegocal.stac.calibration import Calibration
from diegocal.stac.geometry_model import (
    GEOMETRY,
    Layout,
    Spectra,
    State,
    layout,
    log_poses,
    observe,
    pose_means,
    spectra,
    variances,
)
from diegocal.stac.result import StacOptions
from diegocal.stac.stac import calibrate
from diegocal.terms import make_term

LOG = logging.getLogger(__name__)

#: A parameter whose normalised column keeps less than this fraction of its norm once the columns
#: kept before it are projected out is not identifiable (exact redundancies leave ~1e-12).
TOL = 1e-6
#: Gauss-Newton steps at most per noise-model round, and rounds of (fit, re-estimate σ).
MAX_STEPS = 30
ROUNDS = 3
#: A pose's markers are not its own when its χ² passes this tail of χ²_N (as STAC's, :mod:`.poses`).
POSE_TAIL = 1e-6
#: Marker coordinates needed per identifiable parameter (plus ten): fewer leave σ and the
#: standard errors to a handful of degrees of freedom.
MIN_ROWS = 1.5
#: Rounds of "write off, readmit, refit" at most.
WRITE_OFF_ROUNDS = 4


@dataclass(frozen=True)
class Identifiability:
    """Which parameters the poses determine (:func:`identifiable`).

    kept : (p,) bool; alias : (p_kept, p_dropped), the dropped columns in terms of the kept ones
        (J_dropped ≈ J_kept · alias): what the fit calls θ_kept estimates θ_kept + alias θ_dropped;
    condition : 2-norm condition number of the kept, column-normalised, whitened Jacobian;
    residual : (p,) fraction of each column's norm left once the columns kept before it are
        projected out (1 for the first)
    """

    kept: np.ndarray
    alias: np.ndarray
    condition: float
    residual: np.ndarray


@dataclass(frozen=True)
class GeometryFit:
    """A static-pose calibration with link geometry (module docstring).

    calibration : the calibration to write and predict with (its ``terms`` carry one
        ``joint_geometry`` per joint); names, value, stderr : (p,) θ as fitted (frame rotation as a
        left rotation vector about its start), NaN stderr where dropped; identifiability ;
    sigma_markers : m, σ_m; sigma_pots : pot noise s, reading unit; poses : poses used (markers
        kept); rows : marker coordinates fitted; iterations : Gauss-Newton steps in all
    """

    calibration: Calibration
    names: tuple[str, ...]
    value: np.ndarray
    stderr: np.ndarray
    identifiability: Identifiability
    sigma_markers: float
    sigma_pots: float
    poses: int
    rows: int
    iterations: int

    @property
    def pots(self) -> tuple[str, ...]:
        """The pots whose zero or gain the fit determined (a kept ``<pot>.bias`` or ``<pot>.gain``)."""
        kept = [n.rsplit(".", 1) for n, k in zip(self.names, self.identifiability.kept, strict=True) if k]
        return tuple(dict.fromkeys(owner for owner, what in kept if what in ("bias", "gain")))

    @property
    def dropped(self) -> tuple[dict, ...]:
        """``{parameter, reason}`` of each parameter the poses do not determine."""
        ident = self.identifiability
        kept = [n for n, k in zip(self.names, ident.kept, strict=True) if k]
        out = []
        for j, i in enumerate(np.flatnonzero(~ident.kept)):
            coef = ident.alias[:, j]
            top = np.argsort(-np.abs(coef))[:3]
            combo = " ".join(f"{coef[t]:+.3g}·{kept[t]}" for t in top if abs(coef[t]) > 1e-6)
            why = (
                f"its effect on the markers is that of parameters kept ({combo})"
                if combo
                else "it moves no marker in these poses"
            )
            out.append(
                {
                    "parameter": self.names[i],
                    "reason": f"{why}: held at its start (column residual {ident.residual[i]:.1e} < {TOL:g})",
                }
            )
        return tuple(out)

    def to_dict(self) -> dict:
        """calib.yaml's ``geometry`` record: how the fit went and what it could not determine."""
        return {
            "parameters": len(self.names),
            "identifiable": int(self.identifiability.kept.sum()),
            "condition": float(self.identifiability.condition),
            "poses": self.poses,
            "sigma_markers": self.sigma_markers,
            "sigma_pots": self.sigma_pots,
            "pots": list(self.pots),
            "iterations": self.iterations,
            "dropped": list(self.dropped),
        }


# ----------------------------------------------------------------------------- identifiability
def identifiable(Jw: np.ndarray, group: np.ndarray, kept: np.ndarray | None = None) -> Identifiability:
    """The parameters the whitened Jacobian ``Jw`` (N, p) determines (module docstring): groups
    in increasing ``group`` order, each by QR with column pivoting of its normalised columns
    once the kept columns of the groups before it are projected out; a column keeping less than
    TOL of its norm is dropped. ``kept`` (p,) bool: take this set instead (aliases, condition)."""
    norm = np.linalg.norm(Jw, axis=0)
    Jn = Jw / np.where(norm > 0, norm, 1.0)
    if kept is None:
        chosen: list[int] = []
        for g in np.unique(group):
            idx = np.flatnonzero((group == g) & (norm > 0))
            if not len(idx):
                continue
            block = Jn[:, idx]
            if chosen:
                Q, _ = np.linalg.qr(Jn[:, chosen])
                block = block - Q @ (Q.T @ block)
            from_qr = _pivoted(block)
            chosen += [int(idx[i]) for i in from_qr]
        kept = np.zeros(Jw.shape[1], bool)
        kept[chosen] = True
    K = Jn[:, kept]
    if not kept.any():
        raise FitError("no parameter of the geometry fit moves a marker in these poses")
    Q, _ = np.linalg.qr(K)
    residual = np.linalg.norm(Jn - Q @ (Q.T @ Jn), axis=0)
    inv = np.linalg.pinv(K.T @ K)
    residual[kept] = 1.0 / np.sqrt(np.maximum(np.diag(inv), 1e-300))
    alias = np.linalg.lstsq(Jw[:, kept], Jw[:, ~kept], rcond=None)[0]
    s = np.linalg.svd(K, compute_uv=False)
    return Identifiability(kept, alias, float(s[0] / s[-1]), residual)


def _pivoted(block: np.ndarray) -> list[int]:
    """Columns of ``block`` (N, c) kept by QR with column pivoting (|R_ii| > TOL), in pivot order."""
    _, r, piv = qr(block, mode="economic", pivoting=True)
    d = np.abs(np.diag(r))
    return [int(piv[i]) for i in range(len(d)) if d[i] > TOL]


# ----------------------------------------------------------------------------- the fit
def start_state(robot: Robot, cal: Calibration, lay: Layout) -> State:
    return State(
        np.array(cal.mocap_R, float),
        np.array(cal.mocap_T, float),
        np.array(cal.marker_xyz, float),
        np.array(cal.gain, float),
        np.array(cal.bias, float),
        np.zeros((len(lay.geometry), 6)),
    )


def fit_geometry(
    log: Log, robot: Robot, cal: Calibration, poses: np.ndarray | None = None, groups=(0, 1, 2)
) -> GeometryFit:
    """Fit the link geometry with the baseline on the static poses of ``log``, starting at STAC's
    calibration ``cal`` (module docstring). ``poses`` (T,) int: the pose of each sample (default
    :func:`static_poses`). ``groups``: the parameter groups fitted (0 frame and markers, 1 the pots'
    zeros and gains, 2 the geometry; the others held at their start: the bench's reduced models).
    Raises FitError when the poses cannot support the fit.

    The poses whose markers are not their own are those STAC wrote off, re-judged with the
    geometry as :mod:`diegocal.stac.poses` judges them: a pose whose χ² under its covariance C_k
    passes the 1 − POSE_TAIL quantile of χ²_N is written off, one that no longer does is
    readmitted (STAC's, fitted with the URDF's geometry, flags the poses its geometry misses),
    and the model refitted until the set stops changing (at most WRITE_OFF_ROUNDS; never more
    than half the poses, the worst first)."""
    lay = layout(robot, cal)
    data = pose_means(log, cal, poses)
    links = cal.marker_links
    state = start_state(robot, cal, lay)
    var_m = float(cal.sigma_markers) ** 2 if np.isfinite(cal.sigma_markers) else 1e-6
    var_p = max(float(cal.sigma_pots) if np.isfinite(cal.sigma_pots) else 1e-4, 1e-6) ** 2
    written = np.isin(data.ids, [int(r["pose"]) for r in cal.rejected_poses])
    x, J, Jq = observe(robot, lay, state, links, data.pots)
    rw, Jw, _ = spectra(data.without(written).markers - x, J, Jq, lay, state, data).whiten(var_m, var_p)
    kept = identifiable(Jw * np.isin(lay.group, groups), lay.group).kept
    need = MIN_ROWS * kept.sum() + 10
    n_all = int(np.isfinite(data.markers).all(-1).sum()) * 3
    if n_all < need:
        raise FitError(
            f"--geometry: {len(data.ids)} poses give {n_all} marker coordinates for {int(kept.sum())} "
            f"identifiable parameters (at least {MIN_ROWS:g} per parameter + 10 are needed); record more static "
            "poses (diegocal poses proposes them)"
        )
    steps = 0
    for _ in range(WRITE_OFF_ROUNDS):
        used = data.without(written)
        n_rows = int(np.isfinite(used.markers).all(-1).sum()) * 3
        if n_rows < need:  # too few left to judge the others by: every pose is kept
            LOG.warning(f"geometry: writing off {int(written.sum())} pose(s) would leave too few; all are kept")
            written = np.zeros_like(written)
            used, n_rows = data, n_all
        for _ in range(ROUNDS):
            state, n = _gauss_newton(robot, lay, state, links, used, kept, var_m, var_p)
            steps += n
            x, J, Jq = observe(robot, lay, state, links, data.pots)
            spec = spectra(used.markers - x, J, Jq, lay, state, used)
            var_m, var_p = variances(spec, var_m, var_p, n_rows - int(kept.sum()))
        ratio = _disagreement(spectra(data.markers - x, J, Jq, lay, state, data), var_m, var_p, len(data.ids))
        worst = np.argsort(-ratio)[: len(data.ids) // 2]
        new = np.zeros(len(data.ids), bool)
        new[worst[ratio[worst] > 1.0]] = True
        if np.array_equal(new, written):
            break
        written = new
    rw, Jw, _ = spec.whiten(var_m, var_p)
    ident = identifiable(Jw, lay.group, kept)
    cov = np.linalg.inv(Jw[:, kept].T @ Jw[:, kept])
    stderr = np.full(len(lay.names), np.nan)
    stderr[kept] = np.sqrt(np.diag(cov))
    rejected = tuple(
        {
            "pose": int(data.ids[k]),
            "frame": int(data.first[k]),
            "samples": int(data.count[k]),
            "disagreement": float(ratio[k]),
        }
        for k in np.flatnonzero(written)
    )
    calibration = replace(_calibration(cal, lay, state, stderr, var_m, 2 in groups), rejected_poses=rejected)
    LOG.info(f"geometry: {int(kept.sum())} of {len(kept)} parameters identifiable, condition {ident.condition:.3g}")
    fit = GeometryFit(
        calibration,
        lay.names,
        _values(lay, state, cal),
        stderr,
        ident,
        float(np.sqrt(var_m)),
        float(np.sqrt(var_p)),
        int((~written & np.isfinite(data.markers).all(-1).any(-1)).sum()),
        n_rows,
        steps,
    )
    return replace(fit, calibration=_coverage(fit, lay, cal, robot))


def _coverage(fit: GeometryFit, lay: Layout, cal: Calibration, robot: Robot) -> Calibration:
    """The calibration's ``gauges`` and ``unobservable`` as the geometry fit found them (STAC's were
    judged without the geometry): a fitted pot whose bias the poses do not determine is a gauge,
    with the combination it is aliased with; STAC's unobservable pots stay so only where no marker
    moves their joint."""
    why = {d["parameter"]: d["reason"] for d in fit.dropped}
    fitted = {cal.pot_names[i] for i in lay.pots}
    gauges = tuple(
        {
            "joint": robot.joint_names[j],
            "pot": cal.pot_names[i],
            "kind": "geometry",
            "reason": why[f"{cal.pot_names[i]}.bias"],
        }
        for i, j in zip(lay.pots, lay.joints, strict=True)
        if f"{cal.pot_names[i]}.bias" in why
    )
    unobservable = tuple(u for u in cal.unobservable if u.get("pot") not in fitted)
    return replace(fit.calibration, gauges=gauges, unobservable=unobservable)


def _disagreement(spec: Spectra, var_m: float, var_p: float, n_poses: int) -> np.ndarray:
    """Each pose's χ² of its marker residuals under C_k over the 1 − POSE_TAIL quantile of χ²_N
    (N its coordinates; 0 for a pose with none): above 1, its markers are not its own."""
    rw, _, _ = spec.whiten(var_m, var_p)
    d = np.bincount(spec.pose, rw**2, minlength=n_poses)
    n = np.bincount(spec.pose, minlength=n_poses)
    return np.where(n > 0, d / chi2.isf(POSE_TAIL, np.maximum(n, 1)), 0.0)


def _gauss_newton(robot, lay, state, links, data, kept, var_m, var_p) -> tuple[State, int]:
    """Gauss-Newton on the kept parameters at fixed noise levels, halving rejected steps."""
    x, J, Jq = observe(robot, lay, state, links, data.pots)
    rw, Jw, _ = spectra(data.markers - x, J, Jq, lay, state, data).whiten(var_m, var_p)
    cost = float(rw @ rw)
    for step in range(MAX_STEPS):
        delta = np.zeros(len(lay.names))
        delta[kept] = np.linalg.lstsq(Jw[:, kept], rw, rcond=None)[0]
        scale, accepted = 1.0, False
        while scale > 1e-3:
            trial = state.step(lay, scale * delta)
            x, J, Jq = observe(robot, lay, trial, links, data.pots)
            rw_t, Jw_t, _ = spectra(data.markers - x, J, Jq, lay, trial, data).whiten(var_m, var_p)
            c = float(rw_t @ rw_t)
            if c <= cost:
                accepted = True
                break
            scale *= 0.5
        if not accepted:
            return state, step
        done = cost - c <= 1e-9 * max(cost, 1.0)
        state, rw, Jw, cost = trial, rw_t, Jw_t, c
        if done:
            return state, step + 1
    return state, MAX_STEPS


def _values(lay: Layout, state: State, cal: Calibration) -> np.ndarray:
    """θ (p,) in the layout's order (the frame's rotation as a rotation vector of R relative to
    STAC's, so that it is the left perturbation the Jacobian uses)."""
    rot = pin.log3(state.R @ np.asarray(cal.mocap_R, float).T)
    gains = state.gain[lay.pots[lay.gains]]
    return np.concatenate(
        [state.T, rot, state.markers.reshape(-1), state.bias[lay.pots], gains, state.geometry.reshape(-1)]
    )


def _calibration(cal, lay, state, stderr, var_m, geometry: bool = True) -> Calibration:
    """The calibration to write: STAC's with the fitted baseline and (``geometry``) one
    ``joint_geometry`` term per joint (its dropped parameters held at 0 and listed in ``extra``)."""
    M, nb = lay.n_markers, len(lay.pots)
    bias_se = np.array(cal.bias_se if cal.bias_se is not None else np.full(len(cal.pot_names), np.nan), float)
    gain_se = np.array(cal.gain_se if cal.gain_se is not None else np.full(len(cal.pot_names), np.nan), float)
    bias_se[lay.pots] = stderr[6 + 3 * M : 6 + 3 * M + nb]
    gain_se[lay.pots[lay.gains]] = stderr[6 + 3 * M + nb : 6 + 3 * M + nb + int(lay.gains.sum())]
    geo_se = stderr[len(lay.names) - 6 * len(lay.geometry) :].reshape(-1, 6)
    terms = []
    for j, joint in enumerate(lay.geometry if geometry else ()):
        dropped = [a for a, s in zip(GEOMETRY, geo_se[j], strict=True) if not np.isfinite(s)]
        terms.append(
            make_term("joint_geometry", joint, state.geometry[j], extra={"dropped": dropped}, stderr=geo_se[j])
        )
    others = tuple(t for t in cal.terms if t.cause != "joint_geometry")
    return replace(
        cal,
        gain=state.gain,
        bias=state.bias,
        gain_se=gain_se,
        bias_se=bias_se,
        marker_xyz=state.markers,
        marker_xyz_se=stderr[6 : 6 + 3 * M].reshape(M, 3),
        marker_xyz_cov=None,  # STAC's, before the geometry: not this fit's
        mocap_R=state.R,
        mocap_T=state.T,
        sigma_markers=float(np.sqrt(var_m)),
        terms=others + tuple(terms),
        correlations=(),
    )


def calibrate_geometry(
    log: Log, robot: Robot, options: StacOptions | None = None, poses: np.ndarray | None = None
) -> GeometryFit:
    """STAC (:func:`diegocal.stac.stac.calibrate`: the start, and the poses whose markers are not
    their own written off), then :func:`fit_geometry` on the same static poses (FitError, before
    any fit, for a log that is not static poses)."""
    poses = log_poses(log) if poses is None else poses
    cal = calibrate(log.without_truth(), robot, options).calibration
    return fit_geometry(log.without_truth(), robot, cal, poses)


def geometry_calibration(log: Log, robot: Robot, options: StacOptions | None = None) -> Calibration:
    """:func:`calibrate_geometry`'s calibration (the ``fit`` of :func:`~.pose_cv.leave_one_pose_out`)."""
    return calibrate_geometry(log, robot, options).calibration
