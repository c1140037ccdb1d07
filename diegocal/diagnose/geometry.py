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
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from diegocal.diagnose.types import Candidate
from diegocal.errors import FitError
from diegocal.stac.calibration import Calibration
from diegocal.stac.geometry import GeometryFit, calibrate_geometry
from diegocal.stac.geometry_model import GEOMETRY, layout
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
        joints = layout(fitted.applied.robot, fitted.cal).geometry
        term = Term(CAUSE, chain_channel(joints), (Parameter("scale", 0.0, ""),), None, {"joints": list(joints)})
        new = adapter.fit((*fitted.terms, term), train)
    except FitError:
        return None
    before, after = adapter.residuals(fitted).channels, adapter.residuals(new).channels
    cols = {n: np.nan_to_num(before[n] - after[n])[..., None] for n in adapter.marker_names}
    return Candidate(term, cols) if any(np.any(c) for c in cols.values()) else None
