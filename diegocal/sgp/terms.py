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
- ``spring``: stiffness · (q_j − rest_angle − reference) (an elastic element, a gravity
  compensator). The rest angle is a shape parameter: ``diagnose`` proposes the joint's zero, its
  mean training angle and points across its range, and the fit that adds the spring searches it;
  a spring at rest q0 is a spring at q0' beside a ``torque_offset`` of stiffness · (q0' − q0), so
  the rest angle is held where the joint has an offset. ``extra`` reference (rad, default 0): the
  origin of files written before the rest angle was a parameter (their rest angle reads 0);
- ``torque_offset``: a constant bias of joint j's torque sensor;
- ``armature``: the rotor's reflected inertia, inertia · qdd_j;
- ``coupled_friction``: one motor that drives two joints (the TX40's wrist: motor 6 turns with
  q6 + q5): its friction, a function of the motor's velocity v = qd_j + ratio · qd_partner, acts
  on joint j and, times ``ratio``, on the partner (``extra``: partner, ratio);
- ``payload``: an unmodelled point mass on a link (channel: the link): the regressor columns of
  its parent joint's ten inertial parameters (m, m·c, and the second moments about the joint
  frame's origin, Pinocchio's order): a point mass at a lever c has second moments m(|c|²I − ccᵀ),
  not linear in (m, m·c), so they are parameters of their own; ``link_inertia``: the same
  columns, named so where the fitted values are no body (the link's own inertias are wrong);
- ``torque_lag``: the torque sensor of joint j lags (a first-order filter, time constant lag; to
  first order τ_meas ≈ τ − lag · dτ/dt, the column ``diagnose`` proposes). Not a column: the
  model's columns of joint j are filtered (:func:`lag_filter`; linear in the parameters), so it
  needs the samples' time; the lag is fixed when the linear parameters are fitted.
- ``torque_gain``: the torque sensor of joint j (or the motor's torque constant, where torque is
  read from current) reads (1 + gain_error) x the torque. A filter too: the model's columns of
  joint j are scaled; ``diagnose`` proposes the current prediction of joint j as its column.
- ``transmission_backlash``: play between joint j's motor and link; an input filter (the angles
  the columns are evaluated at, :mod:`diegocal.sgp.backlash`), not a sensor's.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from scipy.signal import lfilter

from diegocal.causes import causes_of
from diegocal.errors import InputFileError
from diegocal.sgp.backlash import backlash_proposals, is_input_filter
from diegocal.sgp.bodies import BODIES, body_columns, payloads, restated_only
from diegocal.sgp.proposal import Proposal
from diegocal.terms import Region, Term, make_term

#: The baseline's friction kinds (``SGPOptions.friction``) and the term each one is.
FRICTION_CAUSE = {"viscous": "viscous_friction", "coulomb": "coulomb_friction"}


def friction_column(kind: str, qd: np.ndarray) -> np.ndarray:
    """The friction regressor column of eq. (3.29) for ``kind`` ("viscous" | "coulomb"): qd or sign(qd)."""
    return qd if kind == "viscous" else np.sign(qd)


def is_filter(term: Term) -> bool:
    """True for the sensor causes (:data:`FILTERS`) and a backlash: they filter the model's columns
    (or its angles) instead of adding their own."""
    return term.cause in FILTERS or is_input_filter(term)


def joints_of(term: Term) -> tuple[str, ...]:
    """The joints whose torque a term changes (a payload: none named here, see :func:`columns`)."""
    if term.cause == "coupled_friction":
        return (term.channel, str(term.extra["partner"]))
    return () if term.cause in BODIES else (term.channel,)


def parameter_labels(term: Term) -> tuple[str, ...]:
    """``<cause>:<channel>[<region>].<parameter>``: the names of a term's columns in a model (its
    linear parameters; a shape parameter is no column)."""
    where = ""
    if term.region is not None:
        where = f"[{term.region.low:.3g},{term.region.high:.3g}]"
    if term.cause == "coupled_friction":
        where = f"+{term.extra['partner']}*{float(term.extra['ratio']):g}"
    return tuple(f"{term.cause}:{term.channel}{where}.{p.name}" for p in term.linear)


# ----------------------------------------------------------------------------- behaviours
class Motion:
    """The samples a term's columns are computed on: ``robot``, ``q``, ``qd``, ``qdd`` (T, n), and
    what several terms share, computed once when first asked for (the rigid body's torque: every
    joint's ``load_friction`` reads it). ``rigid``: a callable that gives it, where it is known
    beyond these samples (a chunk of a long log whose every sample's is computed once)."""

    def __init__(self, robot, q, qd, qdd, rigid=None):
        self.robot = robot
        self.q, self.qd, self.qdd = (np.asarray(x, float) for x in (q, qd, qdd))
        self._rigid, self._given = None, rigid

    @property
    def rigid_torque(self) -> np.ndarray:
        """(T, n): the inverse dynamics at the URDF's inertias (RNEA, eq. 3.30 with the file's w)."""
        if self._rigid is None and self._given is not None:
            self._rigid = self._given()
        if self._rigid is None:
            model = self.robot.model
            data = model.createData()
            q, qd, qdd = self.q, self.qd, self.qdd
            self._rigid = np.array([pin.rnea(model, data, q[t], qd[t], qdd[t]) for t in range(q.shape[0])])
        return self._rigid


# Each fills ``out`` (T, n, k): the torque on each joint per unit of each parameter on the samples
# of ``m`` (a :class:`Motion`), joint ``j`` the term's channel (None for a payload, whose channel
# is a link).
def _viscous(term, m, j, out):
    out[:, j, 0] = friction_column("viscous", m.qd[:, j])


def _coulomb(term, m, j, out):
    out[:, j, 0] = friction_column("coulomb", m.qd[:, j])


def _stribeck(term, m, j, out):
    """Friction's shape near zero velocity: sign(qd) e^(−|qd|/scale) per unit of amplitude (a
    Stribeck peak with amplitude > 0; with amplitude < 0 the Coulomb step smoothed over ~scale)."""
    scale = term.value("velocity_scale")
    out[:, j, 0] = np.sign(m.qd[:, j]) * np.exp(-np.abs(m.qd[:, j]) / scale)


def _load_friction(term, m, j, out):
    """Friction in proportion to the load the joint carries, |τ_j| sign(qd_j) per unit of
    coefficient: τ the rigid body's torque at the URDF's inertias (RNEA), the load a gear
    transmits, whose friction grows with it (not the measured torque: it holds the noise and the
    friction itself)."""
    out[:, j, 0] = np.abs(m.rigid_torque[:, j]) * np.sign(m.qd[:, j])


def _position_friction(term, m, j, out):
    inside = term.region.contains(m.q[:, j]).astype(float)
    out[:, j, 0] = inside * np.sign(m.qd[:, j])
    out[:, j, 1] = inside * m.qd[:, j]


def _spring(term, m, j, out):
    out[:, j, 0] = m.q[:, j] - term.value("rest_angle") - float(term.extra.get("reference", 0.0))


def _torque_offset(term, m, j, out):
    out[:, j, 0] = 1.0


def _armature(term, m, j, out):
    out[:, j, 0] = m.qdd[:, j]


def _coupled_friction(term, m, j, out):
    a = m.robot.joint_index(str(term.extra["partner"]))
    ratio = float(term.extra["ratio"])
    v = m.qd[:, j] + ratio * m.qd[:, a]
    cols = np.stack([np.tanh(v / term.value("smoothing")), v], axis=1)
    out[:, j, :] = cols
    out[:, a, :] += ratio * cols


#: cause -> the function that fills its columns (the registry's dynamics terms; the sensor causes
#: are filters, :func:`apply_filters`).
COLUMNS: dict[str, Callable] = {
    "viscous_friction": _viscous,
    "coulomb_friction": _coulomb,
    "stribeck_friction": _stribeck,
    "load_friction": _load_friction,
    "position_friction": _position_friction,
    "spring": _spring,
    "torque_offset": _torque_offset,
    "armature": _armature,
    "coupled_friction": _coupled_friction,
    "payload": body_columns,
    "link_inertia": body_columns,
}


def columns(term: Term, robot, q, qd, qdd) -> np.ndarray:
    """(T, n, k): the torque on each joint per unit of each of ``term``'s parameters (N·m per unit)."""
    return motion_columns(term, Motion(robot, q, qd, qdd))


def motion_columns(term: Term, m: Motion) -> np.ndarray:
    """:func:`columns` on the samples of ``m``: terms computed on the same samples share what
    they have in common (:class:`Motion`)."""
    if is_filter(term):
        raise ValueError(f"{term.cause} filters the model's columns; it has none of its own")
    fill = COLUMNS.get(term.cause)
    if fill is None:
        raise InputFileError(f"{term.cause} is not a dynamics term")
    out = np.zeros((m.q.shape[0], m.q.shape[1], len(term.linear)))
    j = None if term.cause in BODIES else m.robot.joint_index(term.channel)
    fill(term, m, j, out)
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
    m = Motion(robot, q, qd, qdd)
    cols = [motion_columns(t, m) for t in terms if not is_filter(t)]
    if not cols:
        return np.zeros((np.shape(q)[0], robot.n_joints, 0))
    return np.concatenate(cols, axis=2)


# ----------------------------------------------------------------------------- proposals
# How ``diagnose`` proposes each cause on a robot (diegocal.diagnose.dynamics): the terms, or
# variants of one term (a family: the engine keeps the one that fits the training rows best).

#: position_friction: the joint's training range (0.5 %..99.5 % quantiles) is cut into this many
#: equal bins; a region is consecutive bins, at most REGION_MAX_FRACTION of the range, with at
#: least REGION_MIN_FRACTION of the training samples; the REGION_KEEP best on the training
#: residual are offered
REGION_BINS = 64
REGION_MAX_FRACTION = 0.6
REGION_MIN_FRACTION = 0.03
REGION_KEEP = 5
#: coupled_friction: motor velocity qd_j + ratio · qd_partner, the partner the joint before
COUPLING_RATIOS = (1.0, -1.0, 0.5, -0.5, 2.0, -2.0)
#: torque_lag variants: the column of lag L is (filter_L(τ̂) − τ̂) / L (its coefficient ≈ the lag;
#: → −dτ̂/dt as L → 0)
LAG_GRID = (0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2)
#: spring variants beside the joint's zero and mean angle: rest angles at these shares of its training range
SPRING_RESTS = (0.0, 0.25, 0.75, 1.0)
#: stribeck_friction variants: velocity scales, rad/s (the fit that adds it refines the scale)
VELOCITY_SCALES = (0.003, 0.01, 0.03, 0.1, 0.3)


@dataclass(frozen=True)
class Context:
    """What the proposals see of a robot and its current fit.

    robot; joints : the joints with a torque (the model's rows); q, qd (T, n) every joint;
    time (T,) s; train (T,) bool, the training rows; residual, prediction : joint -> (T,) N·m
    of the current fit; terms : the model's terms; baseline_friction : the baseline's friction
    kinds; inertia : "identified" | "nominal"; sensitivity : the motion's ∂τ/∂q (a backlash's columns)
    """

    robot: object
    joints: tuple
    q: np.ndarray
    qd: np.ndarray
    time: np.ndarray
    train: np.ndarray
    residual: dict
    prediction: dict
    terms: tuple
    baseline_friction: tuple
    inertia: str
    sensitivity: object = None

    @property
    def have(self) -> set:
        """{(cause, channel)} of the model's terms."""
        return {(t.cause, t.channel) for t in self.terms}

    def column(self, array: np.ndarray, joint: str, rows=None) -> np.ndarray:
        x = array[:, self.robot.joint_index(joint)]
        return x if rows is None else x[rows]


def proposals(ctx: Context) -> list[Proposal]:
    """Every dynamics term of the registry the model lacks, as :data:`PROPOSE` offers it (default:
    one term per joint with a torque)."""
    out = []
    for cause in causes_of("dynamics", "term"):
        out += PROPOSE.get(cause, _per_joint)(cause, ctx)
    return out


def _per_joint(cause: str, ctx: Context) -> list[Proposal]:
    return [Proposal(make_term(cause, j)) for j in ctx.joints if (cause, j) not in ctx.have]


def _friction(cause: str, ctx: Context) -> list[Proposal]:
    """Viscous or Coulomb friction, where the baseline lacks that kind."""
    kind = next(k for k, c in FRICTION_CAUSE.items() if c == cause)
    return [] if kind in ctx.baseline_friction else _per_joint(cause, ctx)


def _springs(cause: str, ctx: Context) -> list[Proposal]:
    """Springs at rest at the joint's zero, its mean training angle and SPRING_RESTS of its
    training range: the rest angle is not a linear parameter (the fit that adds the spring
    searches it), and a spring proposed at rest far from its own is a spring beside a constant
    torque that a torque offset would take first."""
    out = []
    for j in ctx.joints:
        if (cause, j) not in ctx.have:
            q = ctx.column(ctx.q, j, ctx.train)
            lo, hi = float(np.min(q)), float(np.max(q))
            for rest in (0.0, float(np.mean(q)), *(lo + f * (hi - lo) for f in SPRING_RESTS)):
                out.append(Proposal(make_term(cause, j, {"rest_angle": rest}), f"spring:{j}"))
    return out


def _lags(cause: str, ctx: Context) -> list[Proposal]:
    """A torque sensor's lag: per grid lag, the exact change it makes to the prediction per second,
    held in float32 (a relative 6e-8 of each value, as the projected columns are held)."""
    out = []
    for j in ctx.joints:
        if (cause, j) in ctx.have:
            continue
        pred = ctx.prediction[j]
        for lag in LAG_GRID:
            col = ((lag_filter(pred, ctx.time, lag) - pred) / lag).astype(np.float32)
            out.append(Proposal(make_term(cause, j, {"lag": lag}), f"torque_lag:{j}", {j: col[:, None]}))
    return out


def _gains(cause: str, ctx: Context) -> list[Proposal]:
    """A torque sensor's gain error: the change it makes to the prediction per unit of gain error
    is the prediction itself, judged on every joint's residual (zero columns on the others): the
    fit takes a gain up partly by scaling the inertias, which moves its error onto every joint, and
    judged on its own joint's alone a gain on the joint the inertias serve most looked best (a
    drifting offset on the UR5's elbow gave one on its shoulder). Offered against identified
    inertial parameters only: against the URDF's, a gain and an unmodelled mass read alike (an
    arm3 payload on link3 was named a gain on joint2, which removed 99.9 % of that joint's
    validation error). A common scale of every joint's torque is then the inertias', so a gain on
    the last joint without one is not offered (the model would be degenerate)."""
    left = [j for j in ctx.joints if (cause, j) not in ctx.have]
    if ctx.inertia == "nominal" or len(left) < 2:
        return []
    zero = np.zeros((ctx.q.shape[0], 1))
    return [
        Proposal(make_term(cause, j), columns={k: ctx.prediction[j][:, None] if k == j else zero for k in ctx.joints})
        for j in left
    ]


def _stribeck_scales(cause: str, ctx: Context) -> list[Proposal]:
    """Friction's shape near zero velocity, a family over velocity scales per joint."""
    return [
        Proposal(make_term(cause, j, {"velocity_scale": vs}), f"{cause}:{j}")
        for j in ctx.joints
        if (cause, j) not in ctx.have
        for vs in VELOCITY_SCALES
    ]


def _regions(cause: str, ctx: Context) -> list[Proposal]:
    """position_friction variants: the REGION_KEEP windows of q_j's training range whose two
    columns explain the most of the joint's training residual (exact least squares per window,
    from cumulative sums). A window that reaches an end of the training range comes twice: open
    to the joint's limit there (friction that starts inside the data goes on beyond it) and closed
    at the data's end (it stops there). The training data cannot tell the two apart (their columns
    are equal on every training sample): the selection tests both and the validation data decide."""
    out = []
    for j in ctx.joints:
        if (cause, j) in ctx.have:
            continue
        ok = ctx.train & np.isfinite(ctx.residual[j])
        x, v, r = ctx.column(ctx.q, j, ok), ctx.column(ctx.qd, j, ok), ctx.residual[j][ok]
        i = ctx.robot.joint_index(j)
        for low, high in _best_windows(x, v, r):
            wide = (
                min(low, float(ctx.robot.lower[i])) if low <= x.min() else low,
                max(high, float(ctx.robot.upper[i])) if high >= x.max() else high,
            )
            for lo, hi in dict.fromkeys([wide, (low, high)]):  # open first; closed when it differs
                out.append(Proposal(make_term(cause, j, region=Region(f"q.{j}", lo, hi)), f"position_friction:{j}"))
    return out


def _best_windows(x, v, r) -> list[tuple[float, float]]:
    """(low, high) of the REGION_KEEP best windows of x (module constants), ends at the data's."""
    if x.size < 20:
        return []
    lo, hi = np.quantile(x, [0.005, 0.995])
    if not hi > lo:
        return []
    edges = np.linspace(lo, hi, REGION_BINS + 1)
    b = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, REGION_BINS - 1)
    s = np.sign(v)
    # per bin: Σ s r, Σ v r, Σ s², Σ s v, Σ v²
    sums = np.stack([np.bincount(b, w, minlength=REGION_BINS) for w in (s * r, v * r, s * s, s * v, v * v)])
    cum = np.concatenate([np.zeros((5, 1)), np.cumsum(sums, axis=1)], axis=1)
    counts = np.concatenate([[0], np.cumsum(np.bincount(b, minlength=REGION_BINS))])
    widest = max(1, int(REGION_MAX_FRACTION * REGION_BINS))
    scored = []
    for a in range(REGION_BINS):
        for e in range(a + 1, min(a + widest, REGION_BINS) + 1):
            if counts[e] - counts[a] < REGION_MIN_FRACTION * x.size:
                continue
            sr, vr, ss, sv, vv = cum[:, e] - cum[:, a]
            det = ss * vv - sv * sv
            if det <= 1e-12 * max(ss * vv, 1e-300):
                continue
            scored.append(((vv * sr * sr - 2 * sv * sr * vr + ss * vr * vr) / det, a, e))
    scored.sort(reverse=True)
    # the end windows reach the data's extremes (the quantiles cut no sample off)
    return [
        (float(x.min()) if a == 0 else float(edges[a]), float(x.max()) if e == REGION_BINS else float(edges[e]))
        for _, a, e in scored[:REGION_KEEP]
    ]


def _coupled(cause: str, ctx: Context) -> list[Proposal]:
    """A motor driving a joint and the joint before it, over the ratios of COUPLING_RATIOS ((j,
    partner, ratio) and (partner, j, 1/ratio) are one motor: the joint before only)."""
    coupled = {j for t in ctx.terms if t.cause == cause for j in joints_of(t)}
    out = []
    for j in ctx.joints:
        i = ctx.robot.joint_index(j)
        if j in coupled or i == 0 or ctx.robot.joint_names[i - 1] in coupled:
            continue
        partner = ctx.robot.joint_names[i - 1]
        for ratio in COUPLING_RATIOS:
            term = make_term(cause, j, extra={"partner": partner, "ratio": ratio})
            out.append(Proposal(term, f"coupled_friction:{j}+{partner}"))
    return out


#: cause -> how diagnose proposes it (the rest: one term per joint, :func:`_per_joint`).
PROPOSE: dict[str, Callable] = {
    "viscous_friction": _friction,
    "coulomb_friction": _friction,
    "spring": _springs,
    "stribeck_friction": _stribeck_scales,
    "torque_lag": _lags,
    "torque_gain": _gains,
    "transmission_backlash": backlash_proposals,
    "position_friction": _regions,
    "coupled_friction": _coupled,
    "payload": payloads,
    "link_inertia": restated_only,
}


def lag_filter(X: np.ndarray, time: np.ndarray, lag: float) -> np.ndarray:
    """A first-order lag L·y' + y = x of time constant ``lag`` (s) along axis 0 of X (T, ...),
    causal, started at rest on the first sample, exact for an input linear between samples (a
    first-order hold, so that a lag shorter than a sample delays by about ``lag``):
    y_k = a·y_{k−1} + (1 − c)·x_k + (c − a)·x_{k−1}, a = exp(−h/L), c = (L/h)(1 − a), h the median
    step. A gap in ``time`` (a step over 1.5 × the median) restarts it."""
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


def gain_filter(X: np.ndarray, time: np.ndarray, gain_error: float) -> np.ndarray:
    """A sensor that reads (1 + gain_error) x its input (``time`` unused: the filters' signature)."""
    return (1.0 + gain_error) * np.asarray(X, float)


#: The sensor causes: cause -> filter(X (T, ...), time (T,) s, value) -> what the sensor reads of X
#: (linear in X, so the model's columns are filtered instead; the term's one parameter is the value).
FILTERS: dict[str, Callable] = {"torque_lag": lag_filter, "torque_gain": gain_filter}


def sensor_filter(cause: str, X: np.ndarray, time: np.ndarray, value: float) -> np.ndarray:
    """What a joint's sensor with the filter cause ``cause`` at ``value`` reads of X (T, ...)."""
    return FILTERS[cause](X, time, value)


def needs_time(term: Term) -> bool:
    """True for a filter that runs along the samples' time (``torque_lag``, a backlash's play)."""
    return term.cause == "torque_lag" or is_input_filter(term)


def apply_filters(terms, F: np.ndarray, time: np.ndarray | None, joint_rows: dict) -> np.ndarray:
    """The columns F (T, k, P) with every filter term applied (a lag and a gain on one joint
    compose: both are linear); without ``time`` the lags are left out. ``joint_rows``: joint -> row."""
    filters = [
        t for t in terms if t.cause in FILTERS and t.channel in joint_rows and (time is not None or not needs_time(t))
    ]
    if not filters:
        return F
    out = np.array(F, float, copy=True)
    for t in filters:
        r = joint_rows[t.channel]
        out[:, r, :] = sensor_filter(t.cause, out[:, r, :], time, float(t.values[0]))
    return out
