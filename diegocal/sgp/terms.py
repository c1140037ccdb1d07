"""Terms of a dynamics model: friction and the causes ``diagnose`` adds (thesis eq. 3.29-3.30).

The inverse dynamics are linear in the rigid-body parameters, ``tau = f(q, qd, qdd) w`` (eq. 3.30);
every term here keeps that form: it adds regressor columns ``tau_extra = columns(q, qd, qdd) @ θ``
(shape (T, n, k): the torque on each of the robot's n joints per unit of each of its k
parameters), so that a model with extra terms is fitted by the same linear regression. The
friction of eq. (3.29) is two such terms per joint, ``viscous_friction`` (qd_j η_v,j) and
``coulomb_friction`` (sign(qd_j) η_c,j); :func:`diegocal.sgp.regressor.full_regressor` builds its
friction columns from them.

Causes (DESIGN.md vocabulary, domain ``dynamics``):

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

from dataclasses import dataclass

import numpy as np

from diegocal.errors import InputFileError
from diegocal.terms import Parameter, Region, Term

#: cause -> ((parameter name, unit), ...) in column order.
PARAMETERS: dict[str, tuple[tuple[str, str], ...]] = {
    "viscous_friction": (("viscous", "N·m·s/rad"),),
    "coulomb_friction": (("coulomb", "N·m"),),
    "position_friction": (("coulomb", "N·m"), ("viscous", "N·m·s/rad")),
    "spring": (("stiffness", "N·m/rad"),),
    "torque_offset": (("offset", "N·m"),),
    "armature": (("inertia", "kg·m²"),),
    "coupled_friction": (("coulomb", "N·m"), ("viscous", "N·m·s/rad")),
    "payload": (
        ("mass", "kg"),
        ("mc_x", "kg·m"),
        ("mc_y", "kg·m"),
        ("mc_z", "kg·m"),
        ("I_xx", "kg·m²"),
        ("I_xy", "kg·m²"),
        ("I_yy", "kg·m²"),
        ("I_xz", "kg·m²"),
        ("I_yz", "kg·m²"),
        ("I_zz", "kg·m²"),
    ),
    "torque_lag": (("lag", "s"),),
}
CAUSES = tuple(PARAMETERS)
#: The baseline's friction kinds (``SGPOptions.friction``) and the term each one is.
FRICTION_CAUSE = {"viscous": "viscous_friction", "coulomb": "coulomb_friction"}


def friction_column(kind: str, qd: np.ndarray) -> np.ndarray:
    """The friction regressor column of eq. (3.29) for ``kind`` ("viscous" | "coulomb"): qd or sign(qd)."""
    return qd if kind == "viscous" else np.sign(qd)


@dataclass(frozen=True)
class DynamicsTerm(Term):
    """A term of a dynamics model (see the module docstring): ``columns`` give its torques."""

    @property
    def is_filter(self) -> bool:
        """True for ``torque_lag``: it filters the model's columns instead of adding its own."""
        return self.cause == "torque_lag"

    @property
    def joints(self) -> tuple[str, ...]:
        """The joints whose torque it changes (a payload: none named here, see ``columns``)."""
        if self.cause == "coupled_friction":
            return (self.channel, str(self.extra["partner"]))
        return () if self.cause == "payload" else (self.channel,)

    @property
    def parameter_labels(self) -> tuple[str, ...]:
        """``<cause>:<channel>[<region>].<parameter>``: the names of its columns in a model."""
        where = ""
        if self.region is not None:
            where = f"[{self.region.low:.3g},{self.region.high:.3g}]"
        if self.cause == "coupled_friction":
            where = f"+{self.extra['partner']}*{float(self.extra['ratio']):g}"
        return tuple(f"{self.cause}:{self.channel}{where}.{p.name}" for p in self.parameters)

    def columns(self, robot, q, qd, qdd) -> np.ndarray:
        """(T, n, k): the torque on each joint per unit of each parameter (N·m per unit)."""
        q, qd, qdd = (np.asarray(x, float) for x in (q, qd, qdd))
        T, n = q.shape
        out = np.zeros((T, n, len(self.parameters)))
        if self.cause == "payload":
            return _payload_columns(robot, self.channel, q, qd, qdd)
        if self.is_filter:
            raise ValueError("torque_lag filters the model's columns; it has none of its own")
        j = robot.joint_index(self.channel)
        qj, vj, aj = q[:, j], qd[:, j], qdd[:, j]
        c = self.cause
        if c == "viscous_friction":
            out[:, j, 0] = friction_column("viscous", vj)
        elif c == "coulomb_friction":
            out[:, j, 0] = friction_column("coulomb", vj)
        elif c == "position_friction":
            inside = self.region.contains(qj).astype(float)
            out[:, j, 0] = inside * np.sign(vj)
            out[:, j, 1] = inside * vj
        elif c == "spring":
            out[:, j, 0] = qj - float(self.extra.get("reference", 0.0))
        elif c == "torque_offset":
            out[:, j, 0] = 1.0
        elif c == "armature":
            out[:, j, 0] = aj
        elif c == "coupled_friction":
            a = robot.joint_index(str(self.extra["partner"]))
            ratio = float(self.extra["ratio"])
            v = vj + ratio * qd[:, a]
            cols = np.stack([np.sign(v), v], axis=1)
            out[:, j, :] = cols
            out[:, a, :] += ratio * cols
        else:  # pragma: no cover - make_term refuses unknown causes
            raise ValueError(f"unknown dynamics cause {c!r}")
        return out


def _payload_columns(robot, link: str, q, qd, qdd) -> np.ndarray:
    """The joint-torque regressor's ten columns (m, m·c, second moments; Pinocchio's order) of the
    body that carries ``link`` (a point mass anywhere on it: moments in the parent joint's frame)."""
    import pinocchio as pin

    model = robot.model
    frame = next((f for f in model.frames if f.name == link), None)
    if frame is None or frame.parentJoint == 0:
        raise InputFileError(f"payload: {link!r} is not a moving link of robot {robot.name!r}")
    i = frame.parentJoint - 1  # the body's block of ten columns
    data = model.createData()
    out = np.zeros((q.shape[0], robot.n_joints, 10))
    for t in range(q.shape[0]):
        Y = pin.computeJointTorqueRegressor(model, data, q[t], qd[t], qdd[t])
        out[t] = Y[:, 10 * i : 10 * i + 10]
    return out


def make_term(
    cause: str,
    channel: str,
    region: Region | None = None,
    extra: dict | None = None,
    values: dict | None = None,
) -> DynamicsTerm:
    """A dynamics term of ``cause`` on ``channel`` with its named parameters (values default 0)."""
    if cause not in PARAMETERS:
        raise InputFileError(f"unknown dynamics term cause {cause!r}; known: {', '.join(CAUSES)}")
    if cause == "position_friction" and region is None:
        raise InputFileError(f"position_friction:{channel} needs a region")
    if cause == "coupled_friction" and not {"partner", "ratio"} <= set(extra or {}):
        raise InputFileError(f"coupled_friction:{channel} needs extra {{partner, ratio}}")
    values = values or {}
    params = tuple(Parameter(name, float(values.get(name, 0.0)), unit) for name, unit in PARAMETERS[cause])
    return DynamicsTerm(cause, channel, params, region, dict(extra or {}))


def term_from_dict(d: dict, where: str = "term") -> DynamicsTerm:
    """A dynamics term from its YAML mapping (``Term.to_dict``), parameters checked by name."""
    f = Term.fields_from_dict(d, where)
    if f["cause"] not in PARAMETERS:
        raise InputFileError(f"{where}: unknown dynamics term cause {f['cause']!r}; known: {', '.join(CAUSES)}")
    names = tuple(n for n, _ in PARAMETERS[f["cause"]])
    got = tuple(p.name for p in f["parameters"])
    if got != names:
        raise InputFileError(f"{where}: {f['cause']} has parameters {list(names)}, got {list(got)}")
    units = dict(PARAMETERS[f["cause"]])
    params = tuple(Parameter(p.name, p.value, units[p.name], stderr=p.stderr) for p in f["parameters"])
    return DynamicsTerm(f["cause"], f["channel"], params, f["region"], f["extra"])


def as_dynamics_term(term: Term) -> DynamicsTerm:
    """Any Term with a dynamics cause as a :class:`DynamicsTerm` (values and errors kept)."""
    if isinstance(term, DynamicsTerm):
        return term
    return term_from_dict(term.to_dict())


def friction_terms(joint_names, friction) -> tuple[DynamicsTerm, ...]:
    """The baseline's friction terms: for each kind of ``friction`` (canonical order), one per joint."""
    return tuple(make_term(FRICTION_CAUSE[kind], j) for kind in friction for j in joint_names)


def term_columns(terms, robot, q, qd, qdd) -> np.ndarray:
    """(T, n, K): the columns of every non-filter term, in order (K = their parameters)."""
    cols = [t.columns(robot, q, qd, qdd) for t in terms if not t.is_filter]
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
    lags = [t for t in terms if t.is_filter and t.channel in joint_rows]
    if not lags:
        return F
    out = np.array(F, float, copy=True)
    for t in lags:
        r = joint_rows[t.channel]
        out[:, r, :] = lag_filter(F[:, r, :], time, t.value("lag"))
    return out
