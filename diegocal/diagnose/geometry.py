"""Link geometry as a cause the kinematics diagnosis can name, on static-pose logs (issue #34).

STAC (thesis ch. 2) takes the URDF's link geometry as exact; ``stac --geometry``
(:mod:`diegocal.stac.geometry`) fits every joint's placement deviation ``jointPlacement ·
SE3(exp(r), d)`` (``joint_geometry``) with the baseline from static poses. Here the same fit is a
candidate of the diagnosis, offered only where the log is static poses
(:func:`diegocal.stac.static.static_poses`: the fit needs them, and a moving log's errors are
named by the other terms):

* the **candidate** (:func:`candidate`) is linearised like every kinematic candidate
  (:mod:`.kinematics_lin`): the markers' columns ∂x/∂(d_j, r_j) of every joint that moves a marker,
  at each pose (the geometry fit's own Jacobian, :func:`diegocal.stac.geometry_model.observe`,
  thesis eq. 2.23's way), projected out of each frame's q and of the calibration STAC fits for the
  whole log. It acts on the markers only: the geometry is seen through them, and its held-out
  gain is the markers' error (:meth:`~diegocal.diagnose.types.Finding.gain` pools the channels a
  finding acts on; pots in V beside markers in m would mix units);
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
from diegocal.stac.geometry import GeometryFit, calibrate_geometry, start_state
from diegocal.stac.geometry_model import GEOMETRY, layout, observe, pose_means
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


def fit_chain(log, robot, options, pose_of=None) -> tuple[Calibration, Term]:
    """``stac --geometry``'s fit on ``log`` (the training samples of a static-pose log, mapped into
    the model's other terms; ``pose_of`` as :func:`chain_term`'s): the calibration without its
    geometry terms (the caller composes them into its robot), and the chain's term."""
    fit = calibrate_geometry(log, robot, options)
    cal = fit.calibration
    return replace(cal, terms=tuple(t for t in cal.terms if t.cause != CAUSE)), chain_term(fit, pose_of)


def candidate(lin, fitted, poses: np.ndarray, marker_names) -> Candidate | None:
    """The chain's geometry as a linearised candidate at ``fitted`` (module docstring), or None
    where the geometry fit cannot run (a base link a joint moves, a joint that moves a marker
    without a rotary pot or encoder) or the calibration takes up every direction.

    ``lin`` the :class:`~diegocal.diagnose.kinematics_lin.Linearised` at the fit, ``poses`` (T,)
    int the pose of each sample, ``marker_names`` the log's markers (the channels, in order)."""
    a, cal = fitted.applied, fitted.cal
    try:
        lay = layout(a.robot, cal)
    except FitError:
        return None
    data = pose_means(a.log, cal, poses)
    _, J, _ = observe(a.robot, lay, start_state(a.robot, cal, lay), cal.marker_links, data.pots)
    k = 6 * len(lay.geometry)
    row = np.searchsorted(data.ids, poses)  # each sample's pose
    C = np.zeros((lin.T, lin.R, k))
    for m, name in enumerate(cal.marker_names):
        i = lin.P + 3 * lin.mapped_index(name)
        C[:, i : i + 3] = J[row, m, :, -k:]
    C = lin.beyond_calibration(lin.project(C))
    chans = lin.channels(C) or {}
    cols = {n: chans[n] for n in marker_names if n in chans and np.any(chans[n])}
    if not cols:
        return None
    params = tuple(Parameter(f"{j}.{x}", 0.0, _unit(x)) for j in lay.geometry for x in GEOMETRY)
    term = Term(CAUSE, chain_channel(lay.geometry), params, None, {"joints": list(lay.geometry)})
    return Candidate(term, cols)
