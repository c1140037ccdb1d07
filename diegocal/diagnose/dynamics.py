"""The dynamics adapter of the diagnosis engine: one robot's joint torques (thesis ch. 3).

Baseline: the rigid body + viscous + Coulomb friction model of eq. (3.29)-(3.30), linear in its
base parameters (:func:`diegocal.sgp.regressor.base_parameters`; friction kinds from
``DiagnoseOptions.friction``), fitted by least squares on the training blocks, each joint's rows
weighted by the inverse of its residual std (two passes; the weighting PR's per-joint noise gives).
Channels: the joints with a torque; residual = measured − predicted torque, N·m. Variables:
``q.<j>``, ``qd.<j>``, ``qdd.<j>``, ``time``.

Candidates (:mod:`diegocal.sgp.terms`), all linear in their parameters so that their columns are
exact, per joint: ``torque_offset``, ``spring``, ``armature``, ``viscous_friction`` /
``coulomb_friction`` (when the model lacks them), ``position_friction`` (a family over windows of
the joint's training range), ``torque_lag`` (a family over lags L: column (filter_L(τ̂) − τ̂) / L,
→ −dτ̂/dt as L → 0, its coefficient about the lag in s), ``coupled_friction`` (a family over the
joint before and motor ratios ±½, ±1, ±2). Each candidate's columns come with their least-squares
fit by the current model's columns on every joint's training rows subtracted (Frisch-Waugh-Lovell:
the same estimate and prediction change on its joints as re-fitting the whole model with the term,
for one small regression): a candidate cannot merely take over a baseline part, and the base
parameters an effect distorted are re-adjusted with it. (An engine ``refit`` on the candidate's
joint alone would let any candidate on a joint whose shared parameters an effect elsewhere
distorted outbid the true cause.) A candidate whose columns lie in the model's span (e.g. an
armature on a first joint with a vertical axis) is not offered.

``DiagnoseOptions.inertia``: "identified" (the default, above) offers no ``payload``: a point mass
on a link changes that link's inertial parameters, which the identified rigid body already fits,
so an unmodelled payload is no model error there. "nominal": the rigid body is the URDF's with
its nominal inertias, a fixed part of the prediction (:func:`diegocal.sgp.model.nominal_torque`,
Pinocchio's regressor times the URDF's inertial parameters = RNEA), and only the friction is fitted
(:func:`diegocal.sgp.model.nominal_base`); the candidates add a ``payload`` per moving link (one
body frame per joint, :func:`diegocal.sgp.bodies.payload_links`; channel = that link; columns: the regressor's ten
inertial columns of its body on every measured joint, mass first: a point mass at a lever has
second moments too). A payload parameter whose column lies in the span of the others (the mass
of a link whose origin lies on every earlier joint's axis, a moment along those axes) is reported
with a NaN standard error and a meaningless value: only its moments are identified. Measured
(``tests/diagnose/test_dynamics.py::hidden_payload``: random link of joints 2.., torque
U(3, 10) × noise, seeds 100-109; named = top finding, moments within 10 % or 4 SE, mass within
10 % where identified): arm3 30-s logs 10/10, UR5 15-s 10/10, Panda 15-s 9/10 (a point mass
on link5 named on link6: near joint 6's origin the two are nearly one); clean logs (seeds
200-209) 0 findings in 10 on each robot.

A selected ``torque_lag`` or ``torque_gain`` is refitted as the sensor's filter of the model's
columns (:data:`diegocal.sgp.terms.FILTERS`: first-order, a gain), a ``transmission_backlash`` as
the play that moves the angles the columns are evaluated at (:mod:`diegocal.sgp.backlash`), its
value by a bounded 1-D search with the linear parameters re-solved at each trial
(:mod:`.dynamics_filters`). The
extended model is a dynamics bundle: a PR model (``sgp/`` directory, :mod:`diegocal.sgp.store`)
whose regressor carries the found terms, fitted on the training blocks (``SGPOptions.inertia`` as
diagnosed: a nominal one predicts with the URDF's rigid body + friction + the terms), which
``diegocal predict`` uses like any other.

Where structure stays ``unexplained``, the extended model is the SGP of thesis ch. 3 instead
(:meth:`DynamicsAdapter.absorb`): the same parametric part with a GP per joint on (q, qd), the
library's guard keeping a GP only on the joints where it beats PR in its blocked
cross-validation; the engine keeps it if it lowers the validation error of the unexplained
joints, and measures its gain on the held-out blocks. Measured (``tests/diagnose/
test_dynamics.py::with_bump``: a smooth bump in a joint's angle, which no term expresses, RMS
U(3, 10) × noise, arm3 30-s logs, seeds 0-9): 9 of 10 reported ``unexplained`` on their joint,
held-out RMSE there 0.036-0.082 → 0.0097-0.0165 N·m (noise 0.01); the tenth (4.4 × noise) gave no
finding. The unexplained test bins one variable of the joint at a time (its q, qd, qdd), so a
torque that averages out along each of them (q_{j−1}·qd_j; a bump in q_j times tanh(qd_j)) gives
no finding at all, although the SGP would absorb it (UR5, q_elbow · qd_wrist_1 of RMS 6 × noise:
held-out 0.089 → 0.024 N·m).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from diegocal.diagnose import bodies
from diegocal.diagnose.dynamics_filters import filter_ses, fit_filters
from diegocal.diagnose.dynamics_shapes import fit_shapes, refine_regions, specs, with_region_se, with_shape_se
from diegocal.diagnose.dynamics_system import FamilyRanks, TrainingSystem, feature_chunks, filler, layout, project
from diegocal.diagnose.types import Candidate, Residuals
from diegocal.errors import FitError
from diegocal.evaluate import Score, score
from diegocal.lstsq import CHUNK_ROWS, TallLstsq
from diegocal.sgp.backlash import CAUSE as BACKLASH
from diegocal.sgp.backlash import AngleSensitivity, play
from diegocal.sgp.model import (
    INERTIA,
    INPUT_STREAMS,
    DynamicsModel,
    SGPOptions,
    nominal_base,
    nominal_torque,
    torque_array,
)
from diegocal.sgp.regressor import FRICTION_KINDS, base_parameters, base_regressor, check_friction
from diegocal.sgp.store import ml2_unconverged, save_model
from diegocal.sgp.streams import check_angles, check_torque_scale
from diegocal.sgp.terms import (
    BODIES,
    FILTERS,
    Context,
    dynamics_terms,
    is_filter,
    proposals,
    sensor_filter,
    term_columns,
)

UNIT = "N·m"
#: a candidate column whose residual after projection on its joint's model columns is below this
#: fraction of its norm (training rows) lies in the model's span and is not offered
SPAN_TOL = 1e-6
#: The SGP that absorbs what stays ``unexplained`` (:meth:`DynamicsAdapter.absorb`): the library's
#: defaults (guard on) except that its hyperparameters and the guard's cross-validation use at
#: most 500 training samples (a random subset) instead of 1000: the cost is cubic in it, and on a
#: UR5 log it cost a sixth of the CPU for the same held-out error (fewer starts missed the effect).
EXTENDED_SGP = {"hyper_max": 500}


@dataclass
class DynamicsFit:
    """A fitted torque model (``model``, the :class:`~diegocal.sgp.model.DynamicsModel` that is
    saved): coefficients of [base parameters, extra terms' columns], the terms with their values,
    the per-joint noise std σ_v of the fit and the prediction on every sample (the model's
    columns are not kept: :func:`~diegocal.diagnose.dynamics_system.feature_chunks` rebuilds them)."""

    w: np.ndarray
    terms: tuple
    sigma: np.ndarray
    pred: np.ndarray = field(repr=False)
    train: np.ndarray = field(repr=False)
    model: object = field(repr=False, default=None)  # the fitted DynamicsModel (PR; the SGP once it absorbed)
    gp: tuple | None = None  # the joints where an absorbing SGP kept a GP (None: no SGP)


class DynamicsAdapter:
    """The engine's adapter for one robot's torques (see the module docstring).

    Parameters
    ----------
    robot : diegocal.robot.Robot
    q, qd, qdd : (T, n) every joint, rad, rad/s, rad/s²; tau : (T, k) of ``joints``; time : (T,) s
    friction : the baseline's friction kinds (subset of viscous, coulomb)
    """

    domain = "dynamics"
    #: callable(str) or None: told how far a pass over the log's samples is (the engine sets it)
    progress = None
    #: channel -> the selection's weight of its rows, set by the engine: the candidates it proposes
    #: are then each family's best variant only (:class:`~diegocal.diagnose.dynamics_system.FamilyRanks`)
    selection_weights = None
    #: a gain judged on every joint is refitted against its joint's rivals (a fit is cheap here; a
    #: kinematic one is STAC's alternation): :func:`~diegocal.diagnose.stand_ins.refit_rival`
    refit_rivals = True
    in_span: tuple = ()  # (cause, channel) the last round left unoffered in the model's span (:mod:`.limits`)

    def __init__(self, robot, time, q, qd, qdd, tau, joints, friction=FRICTION_KINDS, inertia="identified"):
        self.robot = robot
        self.unit_name = robot.name
        self.time = np.asarray(time, float)
        self.q, self.qd, self.qdd = (np.asarray(x, float) for x in (q, qd, qdd))
        self.tau = np.asarray(tau, float)
        self.joints = tuple(joints)
        self.friction = check_friction(friction)
        self.rows = [robot.joint_index(j) for j in self.joints]
        self.row_of = {j: r for r, j in enumerate(self.joints)}
        subset = len(self.joints) < robot.n_joints
        if inertia not in INERTIA:
            raise ValueError(f"unknown inertia {inertia!r}; expected one of {', '.join(INERTIA)}")
        self.inertia = inertia
        if inertia == "nominal":  # the URDF's rigid body is fixed; only friction (+ terms) fitted
            self.base = nominal_base(robot, self.friction)
            self.tau0 = nominal_torque(robot, self.q, self.qd, self.qdd)[:, self.rows]
        else:
            self.base = base_parameters(robot, self.friction, rows=self.rows if subset else None)
            self.tau0 = np.broadcast_to(0.0, self.tau.shape)  # zeros that take no memory (read-only)
        self._F = None  # (T, k, r) the base regressor of every sample, built only for a torque_lag
        self._sensitivity = AngleSensitivity(robot, self.q, self.qd, self.qdd, self.rows, self.time)  # every round's
        self._system_of = (None, None)  # (training mask, its TrainingSystem)

    @property
    def F(self) -> np.ndarray:
        """(T, k, r) the base regressor of every sample: held only once a ``torque_lag`` needs it
        (its filter runs along the whole log); every other fit works from :meth:`_system`."""
        if self._F is None:
            self._F = base_regressor(self.robot, self.q, self.qd, self.qdd, self.base, self.friction, self.rows)
        return self._F

    def _system(self, train) -> TrainingSystem:
        """The factored weighted training least squares of ``train`` (built once per training set)."""
        mask, system = self._system_of
        if mask is None or not np.array_equal(mask, train):
            system = TrainingSystem(self, train)
            self._system_of = (np.array(train, bool), system)
        return system

    # ------------------------------------------------------------------ fit
    def _offset(self, lags: dict) -> np.ndarray:
        """(T, k): the fixed part of the prediction (the nominal rigid body's torque, zeros for an
        identified one), at the link angles of a backlash, through each filtering sensor (``lags``:
        (row, cause) -> value)."""
        if not lags or self.inertia != "nominal":
            return self.tau0
        q = self._angles(lags)
        tau0 = self.tau0 if q is self.q else nominal_torque(self.robot, q, self.qd, self.qdd)[:, self.rows]
        return self._lagged(tau0, lags)

    def _angles(self, lags: dict) -> np.ndarray:
        """(T, n): the angles the model's columns are evaluated at: q, each backlash's joint
        through its play (``lags``: (row, cause) -> value); q itself where there is none."""
        moved = {r: v for (r, c), v in lags.items() if c == BACKLASH and v > 0}
        if not moved:
            return self.q
        q = self.q.copy()
        for r, v in moved.items():
            q[:, self.rows[r]] = play(q[:, self.rows[r]], self.time, v)
        return q

    def _model_columns(self, terms, lags: dict, plain=None) -> np.ndarray:
        """(T, k, P): the base regressor and ``terms``' columns at the angles of :meth:`_angles`,
        through the sensors of ``lags``; ``plain``: those columns at the logged angles, if made."""
        q = self._angles(lags)
        if q is not self.q or plain is None:
            C = term_columns(terms, self.robot, q, self.qd, self.qdd)[:, self.rows]
            F = self.F
            if q is not self.q:
                F = base_regressor(self.robot, q, self.qd, self.qdd, self.base, self.friction, self.rows)
            plain = np.concatenate([F, C], axis=2)
        return self._lagged(plain, lags)

    def _solve(self, A, train, sigma, offset=None):
        """Weighted least squares of tau − offset on A (T, k, P) over the training rows, joint rows
        divided by ``sigma``: (w (P,), its covariance (P, P)). The rows are weighed, filtered
        (finite ones only) and factored a chunk at a time (:class:`~diegocal.lstsq.TallLstsq`):
        the training rows of A are never copied whole."""
        offset = self.tau0 if offset is None else offset
        P = A.shape[2]
        ls = TallLstsq(P)
        idx = np.flatnonzero(train)
        step = max(CHUNK_ROWS // A.shape[1], 1)
        for i in range(0, idx.size, step):
            rows = idx[i : i + step]
            X = (A[rows] / sigma[None, :, None]).reshape(-1, P)
            y = ((self.tau[rows] - offset[rows]) / sigma[None, :]).reshape(-1)
            ok = np.isfinite(y) & np.isfinite(X).all(axis=1)
            ls.add(X[ok], y[ok])
        if ls.rows <= P:
            raise FitError(f"too few training torques ({ls.rows}) for {P} parameters")
        w, rss = ls.solve()
        s2 = rss / max(ls.rows - P, 1)
        cov = np.linalg.pinv(ls.gram()) * s2
        return w, cov

    def fit(self, terms, train) -> DynamicsFit:
        """The baseline (eq. 3.30 with friction, base parameters) with ``terms``, fitted on the
        training samples as the model it will be saved as: a PR model (thesis §3.3.3,
        :class:`~diegocal.sgp.model.DynamicsModel`), whose predictions on every sample are the
        residuals' and the held-out scores'. A ``torque_lag``'s time constant and a
        ``torque_gain``'s gain error are searched first (:func:`~.dynamics_filters.fit_filters`,
        weighted least squares), then held in the model."""
        train = np.asarray(train, bool)
        terms = dynamics_terms(terms)
        lags = {self._key(t): float(t.values[0]) for t in terms if is_filter(t) and t.channel in self.row_of}
        regions = any(t.cause == "position_friction" for t in terms)
        if lags or regions or any(p.shape for t in terms for p in specs(t)):
            sigma = self._joint_sigma(terms, train)  # each joint weighted by its residual std
            if lags:
                lags, sigma = fit_filters(self, terms, lags, train, sigma)
                terms = tuple(
                    t.with_values([lags[self._key(t)]]) if is_filter(t) and t.channel in self.row_of else t
                    for t in terms
                )
            terms = fit_shapes(self, terms, lags, train, sigma)
            if regions:
                terms = refine_regions(self, terms, lags, train, sigma)
        rows = train & np.isfinite(self.tau).all(axis=1)
        model = DynamicsModel(self.robot, self._options(), self.joints, terms)
        model.fit_arrays(self.q[rows], self.qd[rows], self.qdd[rows], self.tau[rows], time=self.time[rows])
        pred = model.mean_in_chunks(self.q, self.qd, self.qdd, self.time)
        model.keep_training_mean(pred[rows])
        sigma = np.sqrt(np.asarray(model.gp_.noise_var_, float)).reshape(-1)
        w = model.parametric_.values
        model.unidentified_ = tuple(self._unidentified(model, rows, terms))  # no value, no SE
        out, ses = [], None  # ses: the filter terms' standard errors, made at the first
        for t in model.fitted_terms():
            if is_filter(t):
                if ses is None:
                    ses = filter_ses(self, model, w, lags, pred, rows, sigma)
                se = [ses[self._key(t)]] if t.channel in self.row_of else None
                if t.cause == "torque_gain" and self.inertia != "nominal":  # a common scale is the inertias'
                    t = replace(t, extra={**t.extra, "relative": True})
                out.append(t.with_values(t.values, se))
            elif any(p.shape for p in specs(t)):
                out.append(with_shape_se(self, t, model, pred, rows))
            else:
                out.append(t)
        if regions:  # a region's edges are estimates too: their uncertainty in the coefficients'
            fitted_terms = tuple(out)
            out = [
                with_region_se(self, t, fitted_terms, lags, rows, sigma) if t.cause == "position_friction" else t
                for t in out
            ]
        return DynamicsFit(w, tuple(out), sigma, pred, rows, model)

    def _joint_sigma(self, terms, train) -> np.ndarray:
        """(k,) each joint's training residual std in the unweighted least-squares fit of the
        baseline with ``terms`` (lags not applied): the weights of the searches that follow."""
        system = self._system(train)
        got = system.weighted_fit(terms, np.ones(len(self.joints)))
        if got is not None:
            s = np.sqrt(got[2] / np.maximum(system.counts(), 1))
        else:
            C = term_columns(terms, self.robot, self.q, self.qd, self.qdd)[:, self.rows]
            A = np.concatenate([self.F, C], axis=2)
            w, _ = self._solve(A, train, np.ones(len(self.joints)))
            e = self.tau[train] - (A @ w + self.tau0)[train]
            s = np.sqrt(np.nanmean(e * e, axis=0))
        return np.where(np.isfinite(s) & (s > 0), s, 1.0)

    def _options(self, kind: str = "pr") -> SGPOptions:
        """The options of the model the diagnosis fits and saves ("sgp": it absorbs, EXTENDED_SGP)."""
        options = SGPOptions(kind="pr", friction=self.friction, inertia=self.inertia)
        return replace(options, kind="sgp", **EXTENDED_SGP) if kind == "sgp" else options

    def _unidentified(self, model, train, terms) -> np.ndarray:
        """Indices of A's columns that belong to a body (:data:`BODIES`) and lie in the span of the others on
        the training rows (e.g. the mass of a link whose origin is on every earlier joint's axis:
        only its moments show in the torques): their values are the minimum-norm solution's
        (meaningless); the model gives them none (``DynamicsModel.unidentified_``)."""
        out, at = [], self.base.n_base
        if not any(t.cause in BODIES for t in terms):
            return np.asarray(out, int)
        X = np.concatenate([A for _, A in feature_chunks(model, self, np.flatnonzero(train))])
        X = X.reshape(-1, X.shape[2])
        X = X[np.isfinite(X).all(axis=1)]
        for t in terms:
            if is_filter(t):
                continue
            k = len(t.linear)
            if t.cause in BODIES:
                scale = float(np.linalg.norm(X[:, at : at + k], axis=0).max())
                for p in range(at, at + k):
                    c = X[:, p]
                    norm = float(np.linalg.norm(c))
                    others = np.delete(X, p, axis=1)
                    beta, *_ = np.linalg.lstsq(others, c, rcond=None)
                    if norm <= SPAN_TOL * scale or np.linalg.norm(c - others @ beta) <= SPAN_TOL * norm:
                        out.append(p)
            at += k
        return np.asarray(out, int)

    def _key(self, t) -> tuple:
        """A filter term's key in the fit's ``lags``: (its joint's row, its cause)."""
        return self.row_of[t.channel], t.cause

    def _lagged(self, A, lags: dict):
        """A (T, k, ...) with each filtering sensor applied to its joint's row (``lags``: (row,
        cause) -> value; a lag and a gain on one joint compose; a backlash is no sensor's)."""
        sensors = {k: v for k, v in lags.items() if k[1] in FILTERS}
        if not sensors:
            return A
        out = A.copy()
        for (r, name), value in sensors.items():
            out[:, r] = sensor_filter(name, out[:, r], self.time, value)
        return out

    def _weighted_fit(self, terms, lags: dict, train, sigma) -> tuple:
        """(the linear parameters, the weighted training error) of the model with ``terms``, the
        lags and shapes held: what each trial of a nonlinear search solves. Without lags, from the
        factored training system (:class:`~diegocal.diagnose.dynamics_system.TrainingSystem`: no
        pass over the log); with lags (a filter along the whole log), or where it declines, directly."""
        if not lags:
            got = self._system(train).weighted_fit(terms, sigma)
            if got is not None:
                return got[0], got[1]
        Aeff = self._model_columns(terms, lags)
        offset = self._offset(lags)
        w, _ = self._solve(Aeff, train, sigma, offset)
        e = (self.tau[train] - (Aeff @ w + offset)[train]) / sigma
        return w, float(np.nansum(e * e))

    def _cost(self, terms, lags: dict, train, sigma) -> float:
        """The weighted training error of the model with ``terms`` (the linear parameters solved)."""
        return self._weighted_fit(terms, lags, train, sigma)[1]

    # ------------------------------------------------------------------ residuals and candidates
    def residuals(self, fitted: DynamicsFit) -> Residuals:
        r = self.tau - fitted.pred
        channels = {j: r[:, i] for i, j in enumerate(self.joints)}
        variables = {"time": self.time}
        for s, x in zip(INPUT_STREAMS, (self.q, self.qd, self.qdd), strict=True):
            for i, j in enumerate(self.robot.joint_names):
                variables[f"{s}.{j}"] = x[:, i]
        order = {j: (f"q.{j}", f"qd.{j}", f"qdd.{j}") for j in self.joints}
        context = {j: tuple(f"q.{k}" for k in self.robot.joint_names if k != j) for j in self.joints}
        units = {j: "N" if j in self.robot.prismatic_joints else UNIT for j in self.joints}  # a force on a slide
        return Residuals(channels, units, variables, order, context)

    def candidates(self, fitted: DynamicsFit, residuals: Residuals, train) -> list[Candidate]:
        """Every cause the model lacks, as its behaviour proposes it (:func:`diegocal.sgp.terms.
        proposals`: the registry's dynamics terms), its columns with their fit by the current
        model subtracted (:func:`~diegocal.diagnose.dynamics_system.project`); one whose columns
        lie in the model's span is not offered."""
        train = np.asarray(train, bool)
        self._system_of = (None, None)  # a refit builds it again: its joints' regressors go before the columns come
        ctx = Context(
            self.robot,
            self.joints,
            self.q,
            self.qd,
            self.time,
            train,
            {j: residuals.channels[j] for j in self.joints},
            {j: fitted.pred[:, r] for r, j in enumerate(self.joints)},
            tuple(fitted.terms),
            self.friction,
            self.inertia,
            self._sensitivity,  # a backlash's columns
        )
        props = proposals(ctx)
        width, slots = layout(self, props)
        fill = filler(self, props, width, slots)
        families = None
        if self.selection_weights is not None:  # only each family's best variant is held (FamilyRanks)
            rows = {r: residuals.channels[j] for r, j in enumerate(self.joints)}
            weights = {r: self.selection_weights[j] for r, j in enumerate(self.joints)}
            families = FamilyRanks(rows, weights, [p.family for p in props])
        B, left, slots = project(self, fitted, train, width, slots, fill, self.progress, families)
        props = [(p.term, p.family) for p in props]
        out, self.in_span = [], ()
        for (term, family), slot, f in zip(props, slots, left, strict=True):
            if slot is not None and f > SPAN_TOL:  # each column a view of its joint's block (float32)
                out.append(Candidate(term, {self.joints[r]: B[r][:, sl] for r, sl in slot.items()}, family, visible=f))
            elif slot is not None:
                self.in_span += ((term.cause, term.channel),)
        return out

    # ------------------------------------------------------------------ scores and output
    def score(self, fitted: DynamicsFit, mask, exclude: dict | None = None) -> Score:
        measured = self.tau.copy()
        for c, m in (exclude or {}).items():
            if c in self.row_of:
                measured[np.asarray(m, bool), self.row_of[c]] = np.nan
        return score(measured, fitted.pred, self.joints, unit=UNIT, mask=mask)

    def faults(self, fitted, residuals) -> list:
        return []

    def terms(self, fitted: DynamicsFit):
        return tuple(fitted.terms)

    @staticmethod
    def unconverged(fitted: DynamicsFit) -> tuple:
        """What the fit left at a cap, in words: ML-II runs its iteration cap stopped (none for
        a fit without hyperparameters to learn)."""
        if fitted.model is None or fitted.model.converged_ is not False:
            return ()
        return (ml2_unconverged(*fitted.model.ml2_runs_, fitted.model.options.maxiter),)

    def restate(self, fitted: DynamicsFit, term):
        """A fitted payload no body can be (:func:`bodies.restate`): the fit with it named
        ``link_inertia``, that term and why; None for a body and any other term. The same columns,
        so the fit is renamed, not fitted again."""
        got = bodies.restate(term, self.robot.extent(term.channel)) if term.cause == "payload" else None
        if got is None:
            return None
        other, why = got
        key = (term.cause, term.channel)

        def renamed(terms):
            return tuple(replace(t, cause=other.cause) if (t.cause, t.channel) == key else t for t in terms)

        fitted.model.terms = renamed(fitted.model.terms)  # the saved model names it too
        return replace(fitted, terms=renamed(fitted.terms)), other, why

    def describe(self, fitted: DynamicsFit) -> str:
        base = ("nominal_rigid_body" if self.inertia == "nominal" else "rigid_body") + "".join(
            f"+{k}" for k in self.friction
        )
        parts = [base, *[t.label for t in fitted.terms]]
        if fitted.gp is not None:  # the SGP's GP, on the joints its guard kept one for
            parts.append(f"gp[{','.join(fitted.gp)}]" if fitted.gp else "gp[none kept]")
        return "+".join(parts)

    def absorb(self, fitted: DynamicsFit, channels, train) -> DynamicsFit:
        """The non-parametric part for what stays ``unexplained`` (DESIGN.md: "the non-parametric
        part absorbs it"): the SGP of thesis eq. (3.1)-(3.20) with the found terms in its
        parametric part, fitted on the training blocks with the library's guard: a GP on (q, qd)
        of every joint for each of ``channels`` only, kept by the guard's blocked
        cross-validation only where it beats the parametric model by one standard error; every
        other joint is PR (a GP offered on a joint that needs none extrapolated far off the data
        on a real robot). The engine keeps the result if it lowers the validation error of
        ``channels`` and raises no other channel's."""
        tr = fitted.train
        options = replace(self._options("sgp"), gp_joints=tuple(c for c in self.joints if c in channels))
        model = DynamicsModel(self.robot, options, self.joints, fitted.terms)
        model.fit_arrays(self.q[tr], self.qd[tr], self.qdd[tr], self.tau[tr], time=self.time[tr])
        pred = model.predict_arrays(self.q, self.qd, self.qdd, self.time).tau
        return replace(fitted, pred=pred, model=model, gp=self._kept(model))

    def _kept(self, model) -> tuple:
        """The joints whose GP the model's guard kept."""
        hyper = model.hyperparameters_
        return tuple(j for j in self.joints if hyper[j].get("guard_choice", "parametric") != "parametric")

    def save(self, fitted: DynamicsFit, path, header: dict) -> Path:
        """The extended model as a dynamics bundle; one whose GP absorbs what stays unexplained fitted
        again on the whole log where that fit converges (its gain was measured with the training blocks'
        fit; a GP on 60 % of a session predicted a UR5's next one at 1.72 against 0.24 N·m)."""
        on, m = "training blocks of the diagnosis", fitted.model
        whole = DynamicsModel(self.robot, m.options, self.joints, m.terms) if fitted.gp is not None else None
        if whole is not None and whole.fit_arrays(self.q, self.qd, self.qdd, self.tau, time=self.time).converged_:
            fitted, on = replace(fitted, model=whole, gp=self._kept(whole)), "the whole log (terms from the blocks)"
        meta = {"log": header.get("log"), "command": header.get("command") or "diagnose"}
        meta.update(created=header.get("created"), fitted_on=on, model=self.describe(fitted))
        return save_model(fitted.model, path, meta, header={**header, "kind": "dynamics"})


def _derivative(x: np.ndarray, time: np.ndarray) -> np.ndarray:
    return np.gradient(x, time, axis=0)


def adapters(log, robot, options) -> list[DynamicsAdapter]:
    """One adapter for the robot: q (qd, qdd from the log, else differentiated), tau of the joints
    that have one (``diegocal.sgp.model.torque_array``)."""
    q = log.stream("q", needed_by="diagnose").select(robot.joint_names).data
    check_angles(robot, q)  # degrees: one error line; a joint a little past its limits: a warning
    qd = log.stream("qd").select(robot.joint_names).data if log.has("qd") else _derivative(q, log.time)
    qdd = log.stream("qdd").select(robot.joint_names).data if log.has("qdd") else _derivative(qd, log.time)
    tau, joints = torque_array(log, robot)
    check_torque_scale(robot, q, qd, qdd, tau, joints)  # mN·m: one error line
    friction = getattr(options, "friction", FRICTION_KINDS)
    inertia = getattr(options, "inertia", "identified")
    return [DynamicsAdapter(robot, log.time, q, qd, qdd, tau, joints, friction, inertia)]
