"""The dynamics behaviour of the causes (:mod:`diegocal.causes`): the torque each one adds (thesis eq. 3.29-3.30).

The inverse dynamics are linear in the rigid-body parameters, ``tau = f(q, qd, qdd) w`` (eq. 3.30);
every term here keeps that form: it adds regressor columns ``tau_extra = columns(q, qd, qdd) @ θ``
(shape (T, n, k): the torque on each of the robot's n joints per unit of each of its k
parameters), so that a model with extra terms is fitted by the same linear regression. The
friction of eq. (3.29) is two such terms per joint, ``viscous_friction`` (qd_j η_v,j) and
``coulomb_friction`` (sign(qd_j) η_c,j); :func:`diegocal.sgp.regressor.full_regressor` builds its
friction columns from them.

Causes (the registry's domain ``dynamics``; their parameters and units are the registry's):

- ``viscous_friction`` / ``coulomb_friction``: η_v qd_j, η_c sign(qd_j) on joint j;
- ``position_friction``: the same, only while q_j is in the term's region (cables, a tube
  rubbing near a limit: thesis §3.4.4);
- ``spring``: stiffness · (q_j − reference) (an elastic element, a gravity compensator; ``extra``
  reference, rad, default 0; ``diagnose`` tries the joint's zero and its mean angle, the rest angle
  being no linear parameter); a spring at rest angle q0 is this plus a ``torque_offset`` of
  stiffness · (reference − q0);
- ``torque_offset``: a constant bias of joint j's torque sensor;
- ``armature``: the rotor's reflected inertia, inertia · qdd_j;
- ``coupled_friction``: one motor that drives two joints (the TX40's wrist: motor 6 turns with
  q6 + q5): its friction, a function of the motor's velocity v = qd_j + ratio · qd_partner, acts
  on joint j and, times ``ratio``, on the partner (``extra``: partner, ratio);
- ``payload``: an unmodelled point mass on a link (channel: the link): the regressor columns of
  its parent joint's ten inertial parameters (m, m·c, and the second moments about the joint
  frame's origin, Pinocchio's order): a point mass at a lever c has second moments m(|c|²I − ccᵀ),
  not linear in (m, m·c), so they are parameters of their own;
- ``torque_lag``: the torque sensor of joint j lags (a first-order filter, time constant lag; to
  first order τ_meas ≈ τ − lag · dτ/dt, the column ``diagnose`` proposes). Not a column: the
  model's columns of joint j are filtered (:func:`lag_filter`; linear in the parameters), so it
  needs the samples' time; the lag is fixed when the linear parameters are fitted.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from diegocal.errors import InputFileError
from diegocal.terms import Term, make_term

#: The baseline's friction kinds (``SGPOptions.friction``) and the term each one is.
FRICTION_CAUSE = {"viscous": "viscous_friction", "coulomb": "coulomb_friction"}


def friction_column(kind: str, qd: np.ndarray) -> np.ndarray:
    """The friction regressor column of eq. (3.29) for ``kind`` ("viscous" | "coulomb"): qd or sign(qd)."""
    return qd if kind == "viscous" else np.sign(qd)


def is_filter(term: Term) -> bool:
    """True for ``torque_lag``: it filters the model's columns instead of adding its own."""
    return term.cause == "torque_lag"


def joints_of(term: Term) -> tuple[str, ...]:
    """The joints whose torque a term changes (a payload: none named here, see :func:`columns`)."""
    if term.cause == "coupled_friction":
        return (term.channel, str(term.extra["partner"]))
    return () if term.cause == "payload" else (term.channel,)


def parameter_labels(term: Term) -> tuple[str, ...]:
    """``<cause>:<channel>[<region>].<parameter>``: the names of a term's columns in a model."""
    where = ""
    if term.region is not None:
        where = f"[{term.region.low:.3g},{term.region.high:.3g}]"
    if term.cause == "coupled_friction":
        where = f"+{term.extra['partner']}*{float(term.extra['ratio']):g}"
    return tuple(f"{term.cause}:{term.channel}{where}.{p.name}" for p in term.parameters)


# ----------------------------------------------------------------------------- behaviours
# Each fills ``out`` (T, n, k): the torque on each joint per unit of each parameter, joint ``j``
# the term's channel (None for a payload, whose channel is a link).
def _viscous(term, robot, j, q, qd, qdd, out):
    out[:, j, 0] = friction_column("viscous", qd[:, j])


def _coulomb(term, robot, j, q, qd, qdd, out):
    out[:, j, 0] = friction_column("coulomb", qd[:, j])


def _position_friction(term, robot, j, q, qd, qdd, out):
    inside = term.region.contains(q[:, j]).astype(float)
    out[:, j, 0] = inside * np.sign(qd[:, j])
    out[:, j, 1] = inside * qd[:, j]


def _spring(term, robot, j, q, qd, qdd, out):
    out[:, j, 0] = q[:, j] - float(term.extra.get("reference", 0.0))


def _torque_offset(term, robot, j, q, qd, qdd, out):
    out[:, j, 0] = 1.0


def _armature(term, robot, j, q, qd, qdd, out):
    out[:, j, 0] = qdd[:, j]


def _coupled_friction(term, robot, j, q, qd, qdd, out):
    a = robot.joint_index(str(term.extra["partner"]))
    ratio = float(term.extra["ratio"])
    v = qd[:, j] + ratio * qd[:, a]
    cols = np.stack([np.sign(v), v], axis=1)
    out[:, j, :] = cols
    out[:, a, :] += ratio * cols


def _payload(term, robot, j, q, qd, qdd, out):
    """The joint-torque regressor's ten columns (m, m·c, second moments; Pinocchio's order) of the
    body that carries the link (a point mass anywhere on it: moments in the parent joint's frame)."""
    import pinocchio as pin

    model = robot.model
    frame = next((f for f in model.frames if f.name == term.channel), None)
    if frame is None or frame.parentJoint == 0:
        raise InputFileError(f"payload: {term.channel!r} is not a moving link of robot {robot.name!r}")
    i = frame.parentJoint - 1  # the body's block of ten columns
    data = model.createData()
    for t in range(q.shape[0]):
        Y = pin.computeJointTorqueRegressor(model, data, q[t], qd[t], qdd[t])
        out[t] = Y[:, 10 * i : 10 * i + 10]


#: cause -> the function that fills its columns (the registry's dynamics terms; ``torque_lag`` is
#: a filter, :func:`apply_lags`).
COLUMNS: dict[str, Callable] = {
    "viscous_friction": _viscous,
    "coulomb_friction": _coulomb,
    "position_friction": _position_friction,
    "spring": _spring,
    "torque_offset": _torque_offset,
    "armature": _armature,
    "coupled_friction": _coupled_friction,
    "payload": _payload,
}


def columns(term: Term, robot, q, qd, qdd) -> np.ndarray:
    """(T, n, k): the torque on each joint per unit of each of ``term``'s parameters (N·m per unit)."""
    q, qd, qdd = (np.asarray(x, float) for x in (q, qd, qdd))
    if is_filter(term):
        raise ValueError("torque_lag filters the model's columns; it has none of its own")
    fill = COLUMNS.get(term.cause)
    if fill is None:
        raise InputFileError(f"{term.cause} is not a dynamics term")
    out = np.zeros((q.shape[0], q.shape[1], len(term.parameters)))
    j = None if term.cause == "payload" else robot.joint_index(term.channel)
    fill(term, robot, j, q, qd, qdd, out)
    return out


def dynamics_terms(terms) -> tuple[Term, ...]:
    """``terms`` as a tuple, each checked to be a dynamics term (a cause with columns or a filter)."""
    terms = tuple(terms)
    bad = [t.label for t in terms if t.cause not in COLUMNS and not is_filter(t)]
    if bad:
        raise InputFileError(f"not dynamics terms: {', '.join(bad)}")
    return terms


def friction_terms(joint_names, friction) -> tuple[Term, ...]:
    """The baseline's friction terms: for each kind of ``friction`` (canonical order), one per joint."""
    return tuple(make_term(FRICTION_CAUSE[kind], j) for kind in friction for j in joint_names)


def term_columns(terms, robot, q, qd, qdd) -> np.ndarray:
    """(T, n, K): the columns of every non-filter term, in order (K = their parameters)."""
    cols = [columns(t, robot, q, qd, qdd) for t in terms if not is_filter(t)]
    if not cols:
        return np.zeros((np.shape(q)[0], robot.n_joints, 0))
    return np.concatenate(cols, axis=2)


def lag_filter(X: np.ndarray, time: np.ndarray, lag: float) -> np.ndarray:
    """A first-order lag L·y' + y = x of time constant ``lag`` (s) along axis 0 of X (T, ...),
    causal, started at rest on the first sample, exact for an input linear between samples (a
    first-order hold, so that a lag shorter than a sample delays by about ``lag``):
    y_k = a·y_{k−1} + (1 − c)·x_k + (c − a)·x_{k−1}, a = exp(−h/L), c = (L/h)(1 − a), h the median
    step. A gap in ``time`` (a step over 1.5 × the median) restarts it."""
    from scipy.signal import lfilter

    X = np.asarray(X, float)
    if lag <= 0 or X.shape[0] < 2:
        return X.copy()
    time = np.asarray(time, float)
    steps = np.diff(time)
    h = float(np.median(steps))
    a = np.exp(-h / lag)
    c = lag / h * (1.0 - a)
    cuts = np.concatenate([[0], np.flatnonzero(steps > 1.5 * h) + 1, [X.shape[0]]])
    out = np.empty_like(X)
    for s, e in zip(cuts[:-1], cuts[1:], strict=True):
        seg = X[s:e]
        out[s:e] = lfilter([1.0 - c, c - a], [1.0, -a], seg, axis=0, zi=c * seg[:1])[0]
    return out


def apply_lags(terms, F: np.ndarray, time: np.ndarray, joint_rows: dict) -> np.ndarray:
    """The columns F (T, k, P) with every ``torque_lag`` term applied: row r of joint j through
    :func:`lag_filter` with the term's lag (the sensor's filter, linear in the parameters).
    ``joint_rows``: joint -> row."""
    lags = [t for t in terms if is_filter(t) and t.channel in joint_rows]
    if not lags:
        return F
    out = np.array(F, float, copy=True)
    for t in lags:
        r = joint_rows[t.channel]
        out[:, r, :] = lag_filter(F[:, r, :], time, t.value("lag"))
    return out
