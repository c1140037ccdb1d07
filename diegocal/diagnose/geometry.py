"""Link geometry as a cause the kinematics diagnosis can name, on static-pose logs (issue #34).

STAC (thesis ch. 2) takes the URDF's link geometry as exact; ``stac --geometry``
(:mod:`diegocal.stac.geometry`) fits every joint's placement deviation ``jointPlacement ·
SE3(exp(r), d)`` (``joint_geometry``) with the baseline from static poses. Here the same fit is a
candidate of the diagnosis, offered only where the log is static poses
(:func:`diegocal.stac.static.static_poses`: the fit needs them, and a moving log's errors are
named by the other terms):

* the **candidate** (:func:`candidate`) is the fit itself: its one column per marker is the change
  of the marker's prediction that the geometry fitted on the training poses makes, whose
  coefficient the engine fits on the training rows (1 as fitted) and tests on the validation rows
  as it tests every candidate. A linearised candidate (the geometry's Jacobian projected out of
  each frame's q and of STAC's calibration, as the other kinematic terms are) explained 71 % of
  the training residual of a Talos torso and arm (60 poses) where the fit explains 99.5 %, and
  37 % of the validation residual where the fit explains 99 %. It acts on the markers only: the
  geometry is seen through them, and its held-out gain is the markers' error
  (:meth:`~diegocal.diagnose.types.Finding.gain` pools the channels a finding acts on; pots in V
  beside markers in m would mix units);
* the **fit** of a model that holds it (:func:`fit_chain`) is ``stac --geometry``'s own,
  :func:`~diegocal.stac.geometry.calibrate_geometry` on the training poses: STAC, then the
  Gauss-Newton fit of the identifiable parameters (poses whose markers are not their own written
  off as ``stac --geometry`` writes them off);
* the **finding** is one term for the whole chain (:func:`chain_term`, channel the chain's joints
  joined by ``+`` as a cause tested on several channels at once is named): every joint's six
  parameters with standard errors, and in ``extra`` the parameters the poses identify, the
  dropped ones with the reason, the condition number, the poses fitted and those written off;
* the **extended model** (a calib.yaml) carries one ``joint_geometry`` term per joint
  (:func:`per_joint`), as ``stac --geometry`` writes it, which ``predict`` honours.

Poses whose markers are not their own (a pose filed with another's markers) are a data fault,
``marker_outliers`` with the poses as its samples (:func:`foreign_poses`): the adapter's fits on a
static-pose log write nothing off themselves, so that what ``stac`` and ``stac --geometry`` would
write off in their own fits is reported, left out of the residuals every candidate is fitted and
tested on, and out of the held-out score. A running median of neighbours is meaningless between
poses; each pose is judged whole instead, as :mod:`diegocal.stac.poses` judges it.
"""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np
from scipy.stats import chi2

from diegocal.diagnose.types import Candidate, Fault
from diegocal.errors import FitError
from diegocal.stac.calibration import Calibration
from diegocal.stac.geometry import GeometryFit, calibrate_geometry
from diegocal.stac.geometry_model import GEOMETRY, layout
from diegocal.stac.poses import POSE_TAIL
from diegocal.terms import Parameter, Term, make_term

CAUSE = "joint_geometry"
#: Joins the chain's joints into the finding's channel.
JOIN = "+"
_PREFIX = CAUSE + ":"


def _unit(axis: str) -> str:
    return "m" if axis.startswith("d") else "rad"


def chain_channel(joints) -> str:
    """The channel of the chain's one term: its joints joined by JOIN."""
    return JOIN.join(joints)


def is_chain(term: Term) -> bool:
    """Whether ``term`` is the chain's one geometry term (not a single joint's)."""
    return term.cause == CAUSE and "joints" in term.extra


def chain_term(fit: GeometryFit, pose_of=None) -> Term:
    """The finding's term from a geometry fit: parameters ``<joint>.<dx..rz>`` (m, rad; NaN standard
    error where dropped), ``extra``: joints, identifiable (how many of the fit's parameters the
    poses determine, of how many, and which geometry parameters), dropped (each with its reason),
    condition (of the kept, whitened, column-normalised Jacobian), poses fitted, written_off (the
    poses whose markers are not their own; ``pose_of`` (T',) int: the pose, in the whole log, of
    each sample of the log fitted, default its own poses)."""
    kept = fit.identifiability.kept
    params, kept_geo = [], []
    for i, name in enumerate(fit.names):
        if not name.startswith(_PREFIX):
            continue
        short = name.removeprefix(_PREFIX)
        axis = short.rsplit(".", 1)[1]
        params.append(Parameter(short, float(fit.value[i]), _unit(axis), stderr=float(fit.stderr[i])))
        if kept[i]:
            kept_geo.append(short)
    joints = list(dict.fromkeys(p.name.rsplit(".", 1)[0] for p in params))
    extra = {
        "joints": joints,
        "identifiable": {"count": int(kept.sum()), "of": len(fit.names), "geometry": kept_geo},
        "dropped": [dict(d) for d in fit.dropped],
        "condition": float(fit.identifiability.condition),
        "poses": int(fit.poses),
        "written_off": [
            int(r["pose"] if pose_of is None else pose_of[r["frame"]]) for r in fit.calibration.rejected_poses
        ],
    }
    return Term(CAUSE, chain_channel(joints), tuple(params), None, extra)


def per_joint(term: Term) -> tuple[Term, ...]:
    """The chain's term as one ``joint_geometry`` term per joint (calib.yaml's form, which
    :func:`diegocal.stac.terms.apply_terms` composes into the joints' placements)."""
    out = []
    for joint in term.extra["joints"]:
        names = [f"{joint}.{a}" for a in GEOMETRY]
        by = {p.name: p for p in term.parameters}
        se = [by[n].stderr for n in names]
        dropped = [a for a, s in zip(GEOMETRY, se, strict=True) if not np.isfinite(s)]
        out.append(make_term(CAUSE, joint, [by[n].value for n in names], extra={"dropped": dropped}, stderr=se))
    return tuple(out)


def expand(terms) -> tuple[Term, ...]:
    """``terms`` with the chain's term replaced by its joints' terms (:func:`per_joint`)."""
    out: list[Term] = []
    for t in terms:
        out += per_joint(t) if is_chain(t) else [t]
    return tuple(out)


def fit_chain(log, robot, options, pose_of: np.ndarray) -> tuple[Calibration, Term]:
    """``stac --geometry``'s fit on ``log`` (the training samples of a static-pose log, mapped into
    the model's other terms): the calibration without its geometry terms (the caller composes
    them into its robot), and the chain's term. ``pose_of`` (T',) int: each sample's pose in the
    whole log, whose cut is kept (cut again, the training samples alone can read as one pose: the
    snapshot test compares consecutive samples, and these are poses of several blocks)."""
    fit = calibrate_geometry(log, robot, options, np.unique(pose_of, return_inverse=True)[1])
    cal = fit.calibration
    return replace(cal, terms=tuple(t for t in cal.terms if t.cause != CAUSE)), chain_term(fit, pose_of)


def _unfitted(fitted) -> Term:
    """The chain's term before its fit (the joints ``stac --geometry`` fits on ``fitted``'s robot);
    raises FitError where the geometry fit cannot run."""
    joints = layout(fitted.applied.robot, fitted.cal).geometry
    return Term(CAUSE, chain_channel(joints), (Parameter("scale", 0.0, ""),), None, {"joints": list(joints)})


def candidate(adapter, fitted, train: np.ndarray) -> Candidate | None:
    """The chain's geometry as a candidate at ``fitted`` (module docstring), or None where the
    geometry fit cannot run (a base link a joint moves, a joint that moves a marker without a
    rotary pot or encoder, too few training poses for its identifiable parameters).

    ``adapter`` the :class:`~diegocal.diagnose.kinematics.KinematicsAdapter` (its fit and
    residuals), ``train`` (T,) bool the training samples. The candidate's one column per marker is
    the change of the marker's prediction (T, 3, 1), m, that the geometry fit on the training poses
    makes; its one parameter (``scale``, 1 as fitted) is what the engine fits on the training rows
    and tests on the validation rows like any candidate's."""
    try:
        term = _unfitted(fitted)
        new = adapter.fit((*fitted.terms, term), train)
    except FitError:
        return None
    before, after = adapter.residuals(fitted).channels, adapter.residuals(new).channels
    cols = {n: np.nan_to_num(before[n] - after[n])[..., None] for n in adapter.marker_names}
    return Candidate(term, cols) if any(np.any(c) for c in cols.values()) else None


def foreign_poses(adapter, fitted, swapped: np.ndarray) -> Fault | None:
    """The poses of a static-pose log whose markers are not their own, as a ``marker_outliers``
    fault (``extra``: ``frames`` per marker and ``poses``, the poses in the whole log), or None.

    The poses are judged under the most complete model the training poses support:
    ``stac --geometry``'s fit on them (STAC without the URDF's geometry can make a good pose
    disagree, which the geometry fit readmits), or STAC's where the geometry fit cannot run.
    A pose is foreign when that fit wrote it off, or when its markers' readings, each against its
    prediction by the frame's other sensors (:meth:`KinematicsAdapter.deleted`), give
    D_k = Σ ‖r‖² / s_m² beyond the 1 − POSE_TAIL quantile of χ²_N (N: 3 per reading), s_m² the
    marker's median ‖r‖² over χ²_3's on the training poses kept (a high-breakdown scale, as
    :func:`diegocal.stac.poses.disagreement`'s), and for the other poses, predicted out of sample
    (their error holds the fit's), the larger of that and their own median (on a Panda's 60 poses
    their median error was 1.6 x the training poses': with the training scale a clean pose read as
    foreign). More than half the poses foreign is a wrong model, not wrong data: no fault.
    ``fitted``: the baseline; ``swapped`` (T, M) bool: readings a swap of labels already explains,
    left out."""
    train, poses = fitted.train, adapter.poses
    checked = replace(adapter.options, check_poses=True)
    try:
        judge = adapter.fit_once((_unfitted(fitted),), train, fitted, checked)
        written = next(t for t in judge.terms if is_chain(t)).extra["written_off"]
    except FitError:
        judge = adapter.fit_once((), train, fitted, checked)
        written = [int(poses[train][r["frame"]]) for r in judge.cal.rejected_poses]
    e2 = np.sum(adapter.deleted(judge)[1] ** 2, axis=-1)  # (T, M) m²
    e2 = np.where(swapped, np.nan, e2)
    ok = np.isfinite(e2)
    kept = train & ~np.isin(poses, written)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a marker never seen on those poses: no scale
        s2 = np.nanmedian(np.where(kept[:, None] & ok, e2, np.nan), axis=0)  # (M,) m²
        s2_out = np.nanmedian(np.where(~train[:, None] & ok, e2, np.nan), axis=0)
    s2 = np.where(np.isfinite(s2), s2, np.inf)
    # the other poses' predictions are out of sample (the fit's parameter error adds to the noise)
    s2 = np.where(train[:, None], s2, np.fmax(s2, s2_out))  # (T, M)
    z2 = np.where(ok, e2 / np.maximum(s2 / chi2.median(3), 1e-24), 0.0)
    d = np.bincount(poses, z2.sum(axis=1))
    n = np.bincount(poses, 3 * ok.sum(axis=1))
    bad = (n > 0) & (d > chi2.isf(POSE_TAIL, np.maximum(n, 1)))
    bad[np.asarray(written, int)] = True
    if not bad.any() or bad.sum() > bad.size // 2:
        return None
    mask = bad[poses][:, None] & ok  # (T, M) the foreign poses' readings
    names = adapter.marker_names
    frames = {names[m]: np.flatnonzero(mask[:, m]).tolist() for m in range(len(names)) if mask[:, m].any()}
    if not frames:
        return None
    ch = next(iter(frames)) if len(frames) == 1 else "markers"
    foreign = np.flatnonzero(bad).tolist()
    fault = make_term("marker_outliers", ch, extra={"frames": frames, "poses": foreign})
    evidence = {
        "poses": len(foreign),
        "readings": int(mask.sum()),
        "written_off_by_fit": sorted(int(k) for k in written),
        "tail": POSE_TAIL,
    }
    return Fault(fault, {n: mask[:, names.index(n)] for n in frames}, exclude=True, evidence=evidence)
