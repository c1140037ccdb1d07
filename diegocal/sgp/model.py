"""Inverse-dynamics models of a robot: PR, GP, PRGP and SGP with one interface (thesis ch. 3).

``fit_dynamics(log, robot, SGPOptions(kind=...))`` learns ``tau = f(u) W + Z(u) + V`` from a log
with ``q``, ``qd``, ``qdd`` and ``tau`` streams, where ``u = [q, qd, qdd]`` and ``f`` is the
robot's joint-torque regressor (+ friction) reduced to base parameters
(:mod:`diegocal.sgp.regressor`). The kinds are the special cases of the SGP the thesis lists:

- ``pr``: Bayesian linear regression on the regressor, Z ≡ 0 (thesis eq. 3.25, §3.3.3);
- ``gp``: zero-mean GP per joint, no parametric part (eq. 3.21, §3.3.2);
- ``prgp``: two stages, PR then a GP on its residuals (§3.4.1);
- ``sgp``: W and Z jointly (eq. 3.1-3.20), optionally with the guard (:class:`Guard`).
"""

from __future__ import annotations

import functools
import logging
from dataclasses import dataclass, field

import numpy as np

from diegocal.errors import FitError, MissingStreamError, UnknownNameError
from diegocal.evaluate import nmse  # the one nMSE (thesis §3.4.2), re-exported by diegocal.sgp
from diegocal.parallel import single_threaded
from diegocal.sgp.backlash import link_angles
from diegocal.sgp.estimator import Guard, SemiParametricGP
from diegocal.sgp.kernels import REGION_OFF, Region, SquaredExponential, Subspace, cut_along

# the options and the stream readers have their own modules; their names stay importable from here
from diegocal.sgp.options import (  # noqa: F401
    DEFAULT_GUARD,
    GUARD_GP_INPUTS,
    INERTIA,
    INFERENCE,
    INPUT_STREAMS,
    KINDS,
    MAX_LENGTHSCALE,
    SGPOptions,
    default_guard,
    with_kind,
)
from diegocal.sgp.regressor import (
    BaseParameters,
    base_parameters,
    base_regressor,
    check_friction,
    nominal_torque,
    parameter_names,
)
from diegocal.sgp.streams import check_angles, check_torque_scale, log_arrays, torque_array, warn_unused  # noqa: F401
from diegocal.sgp.terms import (
    apply_filters,
    dynamics_terms,
    is_filter,
    needs_time,
    parameter_labels,
    term_columns,
)
from diegocal.terms import in_slide_units

LOG = logging.getLogger(__name__)
#: Samples whose prediction is made at once where a fit scores itself (nmse_in_sample_): about
#: 40 MB of features for a 7-joint arm with 70 columns, however long the log
PREDICT_SAMPLES = 10_000


@dataclass(frozen=True)
class TorquePrediction:
    """Predicted joint torques (thesis eq. 3.8 and 3.20).

    Attributes
    ----------
    names : tuple of str, joint names (columns)
    tau : ndarray (T, n), posterior mean, N·m (N for prismatic joints)
    tau_std : ndarray (T, n), predictive std of a *measured* torque (latent + noise σ_v)
    tau_std_latent : ndarray (T, n), std of the noise-free torque X(q)
    tau_parametric : ndarray (T, n), the parametric part f(u) ŵ alone (zeros for GP)
    """

    names: tuple
    tau: np.ndarray
    tau_std: np.ndarray
    tau_std_latent: np.ndarray
    tau_parametric: np.ndarray

    def nmse(self, tau_measured: np.ndarray) -> np.ndarray:
        """Normalised MSE per joint: mean squared error / variance of the measurement, (n,)."""
        return nmse(self.tau, tau_measured)


@dataclass(frozen=True)
class ParametricEstimate:
    """Identified base parameters (posterior mean) with standard errors, physical units.

    names : the columns' names (:attr:`DynamicsModel.parameter_names`); values, stderr (P,); cov (P, P)
    """

    names: tuple
    values: np.ndarray
    stderr: np.ndarray
    cov: np.ndarray = field(repr=False)


def nominal_base(robot, friction) -> BaseParameters:
    """The 'base parameters' of a nominal-inertia model: the friction columns of the full
    regressor alone (:func:`~diegocal.sgp.regressor.full_regressor` order), nothing dependent."""

    n = robot.n_joints
    idx = np.arange(10 * n, 10 * n + n * len(check_friction(friction)))
    names = parameter_names(robot, friction)
    return BaseParameters(idx, np.zeros(0, int), np.zeros((idx.size, 0)), tuple(names[i] for i in idx))


class DynamicsModel:
    """A fitted inverse-dynamics model (PR, GP, PRGP or SGP) of one robot.

    Learned attributes: ``parametric_`` (:class:`ParametricEstimate` or None for GP),
    ``hyperparameters_`` (dict per joint, plus ``sigma_w``), ``nmse_in_sample_`` (n,).

    ``terms``: extra terms (:mod:`diegocal.sgp.terms`, e.g. found by ``diagnose``) whose columns
    are appended to the base regressor and fitted with W (their values as given are not read),
    except the sensor causes (``torque_lag``, ``torque_gain``), which filter the columns of their
    joint with their value as given (a lag needs the samples' ``time``), and a
    ``transmission_backlash``, whose play moves the angles every column is evaluated at
    (:mod:`diegocal.sgp.backlash`; it needs the samples' ``time`` too). Without terms the model is
    the one of thesis ch. 3 unchanged.
    """

    def __init__(self, robot, options: SGPOptions, tau_joints=None, terms=(), progress=None):
        self.robot = robot
        self.options = options
        self.progress = progress  # callable(stage, done, total) or None (SemiParametricGP)
        self.terms = dynamics_terms(terms)
        self.joint_names = tuple(robot.joint_names if tau_joints is None else tau_joints)
        unknown = [j for j in self.joint_names if j not in robot.joint_names]
        if unknown or not self.joint_names:
            raise UnknownNameError(
                f"torque joints {unknown or '()'} are not joints of robot {robot.name!r} "
                f"(joints: {', '.join(robot.joint_names)})"
            )
        stray = [j for j in options.gp_joints or () if j not in self.joint_names]
        if stray:  # a misspelt name would leave every joint PR without a word
            raise UnknownNameError(f"gp_joints {stray} are not fitted joints (joints: {', '.join(self.joint_names)})")
        #: the robot joints whose torque rows are fitted (all joints' states enter the regressor)
        self.rows = [robot.joint_index(j) for j in self.joint_names]
        self.joints_without_tau = tuple(j for j in robot.joint_names if j not in self.joint_names)
        n = robot.n_joints
        self.input_names = tuple(f"{s}.{j}" for s in INPUT_STREAMS for j in robot.joint_names)
        gp_streams = options.resolved_gp_inputs()
        self.gp_dims = np.array([INPUT_STREAMS.index(s) * n + i for s in gp_streams for i in range(n)])

    # ------------------------------------------------------------------ building blocks
    def features(self, q, qd, qdd, time=None, sensors: bool = True) -> np.ndarray:
        """Base regressor f(u): (T, k, r), the rows of the k fitted joints; with extra terms,
        (T, k, r + K): their columns appended, a ``torque_gain`` applied, a ``torque_lag`` when
        ``time`` (T,) s is given (or the states are the training samples); without it, states are
        no time series (a grid of a report) and the columns are those of the torque before the
        sensor's lag, at the angles as given (no backlash's play). ``sensors`` False: every sensor's
        filter left out (the torque before the sensors; a backlash is the link's, and stays)."""
        rows = self.rows if self.joints_without_tau else None
        if not self.terms:
            return base_regressor(self.robot, q, qd, qdd, self.base_, self.options.friction, rows)
        time = self._time_of(q, time)
        F = self._columns(link_angles(self.terms, self.robot, q, time) if time is not None else q, qd, qdd, rows)
        return self._filtered(F, q, time) if sensors else F

    def _time_of(self, q, time):
        """``time``, or the training samples' own where ``q`` are the training samples; else None."""
        if time is None and getattr(self, "U_", None) is not None and np.array_equal(q, self.U_[:, : q.shape[1]]):
            return self.time_
        return time

    def _filtered(self, X, q, time):
        """X (T, k, P) through the filter terms' sensors (:func:`~diegocal.sgp.terms.apply_filters`;
        a lag only where the samples' time is known: ``time``, or the training samples' own)."""
        if not any(is_filter(t) for t in self.terms):
            return X
        return apply_filters(self.terms, X, self._time_of(q, time), {j: r for r, j in enumerate(self.joint_names)})

    def _columns(self, q, qd, qdd, rows) -> np.ndarray:
        """(T, k, r + K): the base regressor and the terms' columns (per sample, no lag) side by
        side, written PREDICT_SAMPLES samples at a time into one array: a long log's columns are
        held once, not as two parts and their concatenation."""
        r, T = self.base_.n_base, len(q)
        out = None
        for i in range(0, max(T, 1), PREDICT_SAMPLES):
            sl = slice(i, i + PREDICT_SAMPLES)
            base = base_regressor(self.robot, q[sl], qd[sl], qdd[sl], self.base_, self.options.friction, rows)
            extra = term_columns(self.terms, self.robot, q[sl], qd[sl], qdd[sl])[:, self.rows]
            if out is None:
                out = np.empty((T, base.shape[1], r + extra.shape[2]))
            out[sl, :, :r], out[sl, :, r:] = base, extra
        return out

    def offset(self, q, qd, qdd, time=None) -> np.ndarray:
        """The fixed part of the prediction, (T, k): the nominal rigid body's torque of the fitted
        joints (``inertia="nominal"``; the filter terms applied as to the columns), else zeros."""
        if self.options.inertia != "nominal":
            return np.zeros((np.shape(q)[0], len(self.joint_names)))
        at = self._time_of(q, time)
        link = q if at is None else link_angles(self.terms, self.robot, q, at)
        tau0 = nominal_torque(self.robot, link, qd, qdd)[:, self.rows][:, :, None]
        return self._filtered(tau0, q, time)[:, :, 0]

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """The columns of :meth:`features`: base parameters, then the extra terms' parameters."""
        return tuple(self.base_.names) + tuple(n for t in self.terms if not is_filter(t) for n in parameter_labels(t))

    #: Columns (:attr:`parameter_names` order) the training data do not identify, as judged by the
    #: caller (diagnose: a payload's mass on a link whose origin is on every earlier joint's axis);
    #: :meth:`fitted_terms` gives them no value (NaN): the minimum-norm one means nothing.
    unidentified_: tuple = ()

    def fitted_terms(self) -> tuple:
        """The extra terms with their fitted values and standard errors (a lag and a shape
        parameter as given; an :attr:`unidentified_` column's NaN)."""
        par = self.parametric_
        out, at = [], self.base_.n_base
        for t in self.terms:
            if is_filter(t) or par is None:
                out.append(t)
                continue
            k = len(t.linear)  # its columns; a shape parameter is held as given
            value, se = par.values[at : at + k].copy(), par.stderr[at : at + k].copy()
            gone = np.isin(np.arange(at, at + k), np.asarray(self.unidentified_, int))
            value[gone] = se[gone] = np.nan
            out.append(t.with_linear_values(value, se))
            at += k
        slides = self.robot.prismatic_joints  # a slide's parameters in N, m, kg
        return tuple(in_slide_units(t) if t.channel in slides else t for t in out)

    def _kernels(self):
        """A GP per fitted joint (``options.gp_joints``: those only; the others PR, W shared)."""
        only = self.options.gp_joints
        return [
            Subspace(self.gp_dims, SquaredExponential(len(self.gp_dims))) if only is None or j in only else None
            for j in self.joint_names
        ]

    def _inference(self, N: int) -> str:
        o = self.options
        if o.inference == "auto":
            return "exact" if N <= o.exact_max else "sparse"
        return o.inference

    def _estimator(self, kind: str, N: int, guard: bool) -> SemiParametricGP:
        o = self.options
        g = (o.guard_options or default_guard(o.friction)) if guard else Guard()
        kernels = [None] * len(self.joint_names) if kind == "pr" else self._kernels()
        if guard and g.region and g.joint_region:  # the joint GPs may be cut too (off until then)
            kernels = cut_along(kernels, self._region_inputs())
        return SemiParametricGP(
            kernels,
            use_features=kind != "gp",
            fit_sigma_w=o.fit_sigma_w,
            restarts=o.restarts,
            seed=o.seed,
            guard=g,
            inference=self._inference(N),
            n_inducing=o.n_inducing,
            sparse_tolerance=o.sparse_tolerance,
            hyper_max=o.hyper_max,
            maxiter=o.maxiter,
            jobs=o.jobs,
            min_noise=o.min_noise,
            progress=None if self.progress is None else functools.partial(self.progress, kind),
            region_inputs=self._region_inputs() if guard and g.region else None,
            screen_starts=guard and g.validation_fraction > 0,
        )

    def _region_inputs(self):
        """Per output, the input column of its joint's angle, along which the guard's two-stage GP
        may be cut (:class:`~diegocal.sgp.kernels.Region`); None when the GP does not see angles."""
        n = self.robot.n_joints
        q = INPUT_STREAMS.index("q") * n
        return tuple(q + r if q + r in self.gp_dims else None for r in self.rows)

    # ------------------------------------------------------------------ fit
    @single_threaded
    def fit_arrays(self, q, qd, qdd, tau, state: dict | None = None, time=None) -> DynamicsModel:
        """Fit on q, qd, qdd (T, n) of every joint and tau (T, k) of ``joint_names``; ``state``
        (:meth:`state`) restores a saved fit, no optimising; ``time`` (T,) s for a torque_lag term.
        Raises LogFormatError for q far outside the URDF's limits (:func:`check_angles`: degrees)."""
        q, qd, qdd, tau = (np.asarray(x, float) for x in (q, qd, qdd, tau))
        check_angles(self.robot, q, warn=False)  # the callers that read a log warned of small excursions
        self.time_ = None if time is None else np.asarray(time, float)
        if self.time_ is None and any(needs_time(t) for t in self.terms):
            raise MissingStreamError("fitting a model with a torque_lag or backlash term needs the samples' time")
        o = self.options
        T = len(q)
        if tau.shape != (T, len(self.joint_names)):
            raise ValueError(f"expected tau of shape ({T}, {len(self.joint_names)}), got {tau.shape}")
        if state is not None:
            self.base_ = BaseParameters.from_dict(state["base"])
        elif o.inertia == "nominal":
            self.base_ = nominal_base(self.robot, o.friction)
        else:
            rows = self.rows if self.joints_without_tau else None
            self.base_ = base_parameters(self.robot, o.friction, seed=o.seed, rows=rows)
        r = self.base_.n_base
        need = max(10, int(np.ceil((r + 1) / len(self.joint_names)))) if o.kind != "gp" else 10
        if T < need:
            raise FitError(
                f"too few samples to fit a {o.kind} model: {T}, need at least {need} "
                f"({r} base parameters, {len(self.joint_names)} joints)"
            )
        U = np.hstack([q, qd, qdd])
        self.U_, self.tau_ = U, tau
        tau = tau - self.offset(q, qd, qdd, self.time_)  # nominal inertias: W fits the rest
        st = state or {}
        if o.kind == "pr" and not any(needs_time(t) for t in self.terms):  # features a chunk at a time
            est = self._estimator("pr", T, False)
            features = lambda rows: self.features(q[rows], qd[rows], qdd[rows])  # noqa: E731
            self.gp_ = est.fit_in_chunks(U, tau, features, st.get("hyper"))
            self._nmse = None  # made when first read: a pass over the training features
            return self
        F = self.features(q, qd, qdd, self.time_)
        if o.kind == "prgp":
            self.pr_ = self._estimator("pr", T, False).fit(U, tau, F, st.get("hyper_pr"), st.get("inducing_pr"))
            resid = tau - self.pr_.predict(U, F, variance=False)[0]
            self.gp_ = self._estimator("gp", T, False).fit(U, resid, F, st.get("hyper"), st.get("inducing"))
        else:
            est = self._estimator(o.kind, T, o.guard_active)
            args = (st.get("hyper"), st.get("inducing"), st.get("stages"), st.get("inducing_res"))
            self.gp_ = est.fit(U, tau, F, *args, overwrite_features=o.kind == "pr")  # F not read again
        del F
        self._nmse = None
        return self

    @property
    def nmse_in_sample_(self) -> np.ndarray:
        """(n,) the fit's normalised MSE on its own training samples, made when first read (a fit
        that is never saved nor shown, as most of a diagnosis's are, skips that pass)."""
        if getattr(self, "_nmse", None) is None:
            if getattr(self, "U_", None) is None:
                raise AttributeError("nmse_in_sample_: the model is not fitted")
            q, qd, qdd = np.split(self.U_, 3, axis=1)
            self._nmse = nmse(self.mean_in_chunks(q, qd, qdd, self.time_), self.tau_)
        return self._nmse

    def keep_training_mean(self, mean: np.ndarray) -> None:
        """Take ``mean`` (T_train, k), the posterior mean on the training samples from a pass the
        caller made anyway, as :attr:`nmse_in_sample_`'s, sparing that pass. A model with a filter
        along time (a lag, a play) runs it over the training samples as a series of their own:
        that one makes its own."""
        if not any(needs_time(t) for t in self.terms):
            self._nmse = nmse(mean, self.tau_)

    def mean_in_chunks(self, q, qd, qdd, time) -> np.ndarray:
        """(T, k) the posterior mean torque at states (T, n) each, PREDICT_SAMPLES at a time, so
        that a long log's features are never built whole (all at once for a model with a
        ``torque_lag``, whose filter runs along the whole series)."""
        if any(needs_time(t) for t in self.terms):
            return self.predict_arrays(q, qd, qdd, time, variance=False).tau
        out = np.empty((len(q), len(self.joint_names)))
        for i in range(0, len(q), PREDICT_SAMPLES):
            sl = slice(i, i + PREDICT_SAMPLES)
            out[sl] = self.predict_arrays(q[sl], qd[sl], qdd[sl], None, variance=False).tau  # time: lags only
        return out

    @property
    def _param_est(self) -> SemiParametricGP | None:
        return {
            "pr": getattr(self, "gp_", None),
            "sgp": getattr(self, "gp_", None),
            "prgp": getattr(self, "pr_", None),
        }.get(self.options.kind)

    @property
    def ml2_runs_(self) -> tuple[int, int]:
        """(ML-II's L-BFGS-B runs of the fit, those its iteration cap stopped): every estimator's
        (PRGP: the PR stage's and the GP's)."""
        parts = [e.ml2_runs_ for e in (getattr(self, "pr_", None), getattr(self, "gp_", None)) if e is not None]
        return sum(p[0] for p in parts), sum(p[1] for p in parts)

    @property
    def converged_(self) -> bool | None:
        """Whether no ML-II run of the fit stopped at its iteration cap; None when none ran (a
        restored fit)."""
        runs, capped = self.ml2_runs_
        return None if runs == 0 else capped == 0

    @property
    def prior_share_(self) -> np.ndarray | None:
        """(P,) each parametric column's posterior variance over its prior's (σ_w, thesis eq. 3.25):
        near 0 where the data fix the parameter, 1 where they say nothing of it (a joint that never
        moves: its friction is the prior's 0 ± σ_w); in between, the share of the way its estimate
        is pulled toward 0. None for a model without a parametric part."""
        est = self._param_est
        if est is None or getattr(est, "hyper_", None) is None:
            return None
        prior = (np.exp(est.hyper_.log_sigma_w) / est.f_scale_) ** 2
        return np.diag(est.w_cov_) / prior

    @property
    def parametric_(self) -> ParametricEstimate | None:
        est = self._param_est
        if est is None:
            return None
        std = np.sqrt(np.maximum(np.diag(est.w_cov_), 0.0))
        return ParametricEstimate(self.parameter_names, est.w_.copy(), std, est.w_cov_.copy())

    @property
    def hyperparameters_(self) -> dict:
        """σ_w, and per joint σ_v, σ_z and length-scales (the input's unit) of the model that
        predicts it: for a joint the guard gave two stages (``guard_choice`` "two-stage"), those
        of its GP on PR's residual, with PR's σ_v as ``sigma_v_pr``."""
        est = self.gp_
        hp = est.hyper_
        out = {"sigma_w": float(np.exp(hp.log_sigma_w)) if self.options.kind != "gp" else None}
        pr_noise = np.exp(self.pr_.hyper_.log_sigma_v) if self.options.kind == "prgp" else None
        stages = getattr(est, "stages_", None)
        for j, joint in enumerate(self.joint_names):
            gp, dims, noise = est, self.gp_dims, pr_noise
            if stages is not None and stages.mode(j) == "two-stage":
                gp, noise = est.residual_, np.exp(stages.pr.log_sigma_v)
            entry = {"sigma_v": float(np.exp(gp.hyper_.log_sigma_v[j]))}
            if noise is not None:
                entry["sigma_v_pr"] = float(noise[j])
            if est.kernels[j] is not None:
                th = gp.hyper_.theta[j]
                if isinstance(gp.kernels[j], Region):  # cut at an onset in the joint's angle
                    d = gp.kernels[j].dim
                    if th[0] < REGION_OFF:
                        entry["region"] = {
                            "input": self.input_names[d],
                            "onset": float(th[0] * gp.u_std_[d] + gp.u_mean_[d]),
                            "width": float(np.exp(th[1]) * gp.u_std_[d]),
                            "ratio": float(np.exp(th[2])),
                        }
                    th = th[3:]
                entry["sigma_z"] = float(np.exp(th[0]))
                # length-scales back in the input's unit (inputs were standardised)
                scaled = np.exp(th[1 : 1 + len(dims)])  # in units of the input's training std
                names = [self.input_names[d] for d in dims]
                entry["lengthscales"] = dict(zip(names, map(float, scaled * est.u_std_[dims]), strict=True))
                # how fine a detail of this session's path the GP follows (report: fine GP detail)
                entry["lengthscales_std"] = dict(zip(names, map(float, scaled), strict=True))
                if hasattr(est, "selection_"):  # the guard's cross-validated choice (fits only)
                    entry["guard_choice"] = est.selection_[j]
                    scores = getattr(est, "validation_scores_", None)  # a fit's, not a restored model's
                    if scores is not None:  # the blocked cross-validation's nMSE the choice was made on
                        weighed = [(k, v[j]) for k, v in scores.items() if k != "cut" or np.isfinite(v[j])]
                        entry["guard_validation"] = {k: float(v) for k, v in weighed}  # "cut" where it cuts
                if gp.inference == "sparse":  # inducing inputs, and the prior variance they miss
                    entry["n_inducing"] = int(gp.n_inducing_[j])
                    entry["sparse_gap"] = float(gp.sparse_gap_[j])
            out[joint] = entry
        return out

    # ------------------------------------------------------------------ predict
    @single_threaded
    def predict_arrays(self, q, qd, qdd, time=None, variance: bool = True) -> TorquePrediction:
        """Predict torques for states (T, n) each (rad, rad/s, rad/s²); ``time`` (T,) s matters
        only to a model with a torque_lag term (without it: the torque before the sensor's lag).
        Without ``variance`` the stds are NaN (the mean alone is far cheaper for an exact GP)."""
        q, qd, qdd = (self.robot.check_q(x) for x in (q, qd, qdd))
        U = np.hstack([q, qd, qdd])
        F = self.features(q, qd, qdd, time)
        mean, var, par = self.gp_.predict(U, F, variance)
        noise = self.gp_.noise_var_
        if self.options.kind == "prgp":
            m_pr, v_pr, par = self.pr_.predict(U, F, variance)
            mean = mean + m_pr
            var = None if var is None else var + v_pr  # two independent stages: variances add
        if self.options.inertia == "nominal":
            tau0 = self.offset(q, qd, qdd, time)
            mean, par = mean + tau0, par + tau0
        if var is None:
            var = np.full_like(mean, np.nan)
        latent = np.sqrt(np.maximum(var, 0.0))
        return TorquePrediction(self.joint_names, mean, np.sqrt(var + noise), latent, par)

    def predict(self, log) -> TorquePrediction:
        q, qd, qdd = log_arrays(log, self.robot, need_tau=False)
        return self.predict_arrays(q, qd, qdd, log.time)

    # ------------------------------------------------------------------ persistence
    def state(self) -> dict:
        """All needed to rebuild the posterior without optimising (:mod:`diegocal.sgp.store`)."""
        st = {
            "base": self.base_.to_dict(),
            "hyper": self.gp_.hyper_,
            "inducing": self.gp_.inducing_,
        }
        if self.options.kind == "prgp":
            st["hyper_pr"], st["inducing_pr"] = self.pr_.hyper_, self.pr_.inducing_
        if getattr(self.gp_, "stages_", None) is not None:  # the guard's two stages (Guard.two_stage)
            st["stages"] = self.gp_.stages_
            st["inducing_res"] = None if self.gp_.residual_ is None else self.gp_.residual_.inducing_
        return st


def fit_dynamics(log, robot, options: SGPOptions | None = None, progress=None) -> DynamicsModel:
    """Fit an inverse-dynamics model (``options.kind``) to a log with q, qd, qdd and tau streams.

    ``options`` default to ``SGPOptions()``. ``progress``: callable(model kind, stage, done, total)
    or None, told as the hyperparameter starts, the guard's cross-validation and the posterior
    finish. BLAS runs on one thread; ``options.jobs`` threads share the independent work
    (:mod:`diegocal.parallel`).

    q, qd and qdd must cover every joint of the robot; ``tau`` may cover a subset: the model is
    then fitted on (and predicts) the torques of the joints that have one, while every joint's
    motion still enters their regressor rows (thesis eq. 3.30); the others are logged and listed
    in ``model.joints_without_tau``. Channels that are no joint of the robot (a gripper's motor, a
    joint the model holds still) are left out with one warning (:mod:`diegocal.sgp.streams`).
    Fitting never reads ``log.truth``.
    """
    options = options or SGPOptions()
    log = log.without_truth()
    q, qd, qdd = log_arrays(log, robot, need_tau=False, needed_by="sgp-fit", warn=False)
    tau, joints = torque_array(log, robot, warn=False)
    check_torque_scale(robot, q, qd, qdd, tau, joints)
    warn_unused(log, robot, INPUT_STREAMS + ("tau",))  # a gripper's channels, a locked joint's
    model = DynamicsModel(robot, options, tau_joints=joints, progress=progress)
    if model.joints_without_tau:
        LOG.warning(
            "no torque for joint(s) %s: fitting the torques of %s only (their motion still enters the regressor)",
            ", ".join(model.joints_without_tau),
            ", ".join(joints),
        )
    return model.fit_arrays(q, qd, qdd, tau)
