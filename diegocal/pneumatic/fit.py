"""Next-step least squares for the valve-chamber model (thesis §4.5.3, the equation after 4.11).

.. math:: c^* = \\arg\\min_c \\sum_t (p_{t+h} - \\hat p_{t+h}(p_t, u_t, v_t, \\dot v_t; c))^2

with p̂ the exact step (4.7) of the model's terms (c1..c9 of eq. 4.10 and any extra terms,
:class:`~diegocal.pneumatic.model.ChamberModel`), bounds of Table 4.1 (plus ``|c6| < 1`` on the
normalised volume coordinate) and of the extra terms, and an analytic Jacobian for scipy's
``trf``. Parameters are packed by name at the optimiser's door only.

Standard errors are cluster-robust (sandwich) over contiguous blocks of :data:`SE_BLOCK_S` of
steps: the residuals of a 100 Hz next-step fit are correlated in time (the model's own error
follows the command's holds), so s² (JᵀJ)⁻¹ understated them, a valve delay's many times over.
Blocks never span a gap or a block edge of the fitted rows.
"""

from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.optimize import least_squares

from diegocal.errors import DiegocalError, FitError
from diegocal.evaluate import sub_blocks

try:  # BLAS threads only slow down trf's SVD of a tall, 9-column Jacobian (measured: ~5x)
    from threadpoolctl import threadpool_limits
except ImportError:  # pragma: no cover - optional
    threadpool_limits = None
import diegocal.pneumatic.params as P
from diegocal.pneumatic.data import ChamberData
from diegocal.pneumatic.model import ChamberModel
from diegocal.pneumatic.params import ChamberParams
from diegocal.pneumatic.predict import drift, line_state
from diegocal.terms import correlated_pairs, write_correlated


@dataclass(frozen=True)
class FitOptions:
    """Options of a chamber fit, parsed once.

    jacobian : "analytic" or "2-point" (finite differences; the reference in the bench)
    starts : number of starting points (1 = Table 4.1's start values; more adds seeded random ones)
    seed : seed of the random starting points
    max_nfev : evaluation budget per start
    drift_starts, horizon_s : the multi-step check stored with the fit (§4.5.4)
    """

    jacobian: str = "analytic"
    starts: int = 1
    seed: int = 0
    max_nfev: int = 200
    tol: float = 1e-10
    drift_starts: int = 48
    horizon_s: float = 2.0


@dataclass(frozen=True)
class ChamberFit:
    """The fitted model of one chamber with its diagnostics.

    params : ChamberParams (values, standard errors); cost : 0.5 * sum of squared residuals (pu²)
    rmse : next-step RMS residual (pu); n_samples : residuals used; nfev : evaluations (best start)
    drift_2s : open-loop RMS error at the horizon / (P_c - P_r) on the fitted log (§4.5.4)
    drift_curve : that fraction every 0.1 s of horizon
    start_costs : final cost from every start (multi-start spread; §4.5.3's convergence claim)
    start_params : (starts, 9) parameters reached from every start
    covariance : (P, P) cluster-robust covariance of c1..c9 and the extra terms' parameters (the
        order of ``params.full_vector()``), NaN where a direction is not identified
    converged : the kept start's least squares ended at its tolerance (False: at its evaluation
        budget, ``FitOptions.max_nfev``)
    """

    name: str
    params: ChamberParams
    cost: float
    rmse: float
    n_samples: int
    nfev: int
    drift_2s: float
    drift_curve: list = field(default_factory=list)
    start_costs: tuple = ()
    start_params: np.ndarray | None = None
    covariance: np.ndarray | None = field(default=None, repr=False)
    converged: bool = True

    def correlation(self, a: str, b: str) -> float:
        """The correlation of the estimates of parameters ``a`` and ``b`` (names of c1..c9 or of the
        extra terms' parameters); NaN when either is not identified or not in the model."""
        names = list(self.params.names())
        if self.covariance is None or a not in names or b not in names:
            return float("nan")
        i, j = names.index(a), names.index(b)
        c = self.covariance
        return float(c[i, j] / np.sqrt(c[i, i] * c[j, j])) if c[i, i] > 0 and c[j, j] > 0 else float("nan")

    def to_dict(self) -> dict:
        out = self.params.to_dict(self.name)
        out["converged"] = bool(self.converged)
        if self.covariance is not None:  # estimates that trade off, as calib.yaml writes STAC's
            labels = [f"{self.name}.{n}" for n in self.params.names()]
            write_correlated(out["baseline"] + out.get("terms", []), correlated_pairs(self.covariance, labels))
        out.update(
            cost=self.cost,
            rmse=self.rmse,
            n_samples=self.n_samples,
            drift_2s=self.drift_2s,
            drift_curve=self.drift_curve,
        )
        if len(self.start_costs) > 1:
            out["start_costs"] = [float(c) for c in self.start_costs]
        return out


def volume_normalisation(v: np.ndarray) -> tuple[float, float]:
    """(v_ref, v_scale): centre and half-range of the volume sensor on the fitting data.

    A sensor that never moves (locked cylinder) gets scale 1: c4-c6 are then unidentifiable and
    the fit reports NaN standard errors for them.
    """
    lo, hi = float(np.min(v)), float(np.max(v))
    half = 0.5 * (hi - lo)
    return 0.5 * (hi + lo), half if half > 1e-9 * max(1.0, abs(lo), abs(hi)) else 1.0


def step_rows(data: ChamberData, rows: np.ndarray | None = None) -> np.ndarray:
    """Indices t of the steps t -> t+1 used by a fit: not across a gap in the recording and, when
    ``rows`` (T,) bool is given, with both t and t+1 in ``rows`` (never across a block edge)."""
    ok = data.steps.copy()
    if rows is not None:
        rows = np.asarray(rows, bool)
        ok &= rows[:-1] & rows[1:]
    return np.flatnonzero(ok)


class _Problem:
    """Residuals and Jacobian of the next-step fit, sharing one evaluation per x."""

    def __init__(
        self,
        data: ChamberData,
        nominal: ChamberParams,
        model: ChamberModel | None = None,
        rows: np.ndarray | None = None,
        weights: np.ndarray | None = None,
    ):
        self.model = model or ChamberModel()
        sl = step_rows(data, rows)  # pairs (t, t+1) that do not straddle a gap
        self.w = None if weights is None else np.asarray(weights, float)[sl]
        v, vd = nominal.volume_coordinate(data.v[sl], data.vd[sl])
        self.args = (data.p[sl], data.u[sl], v, vd, np.diff(data.time)[sl])
        self.target = data.p[sl + 1]
        self.rows = sl
        self.consts = (nominal.c_b, nominal.c_s, nominal.c_gamma)
        h = float(np.median(np.diff(data.time)))
        self.lags = data.u_lags(self.model.n_lags(h))[sl] if self.model.has_delay else None
        self.data, self.nominal, self.fit_rows = data, nominal, rows
        self._x = None
        self._cache = None

    def _line(self, x, jacobian: bool):
        """The supply hose's sag on the fitted steps (None without a hose), its observer reset at
        every block edge of the fitted rows (:func:`~diegocal.pneumatic.predict.line_state`)."""
        line = line_state(self.model, x, self.nominal, self.data, self.fit_rows, jacobian)
        return None if line is None else line.take(self.rows)

    def _eval(self, x, jacobian: bool):
        if (
            self._x is not None
            and np.array_equal(x, self._x)
            and (self._cache[1] is not None or not jacobian)
        ):
            return self._cache
        p, u, v, vd, h = self.args
        line = self._line(x, jacobian)
        out = self.model.step(x, p, u, v, vd, h, *self.consts, self.lags, jacobian=jacobian, line=line)
        self._x, self._cache = np.array(x), out
        return out

    def residuals(self, x):
        r = self._eval(x, jacobian=True)[0] - self.target
        return r if self.w is None else self.w * r

    def residuals_only(self, x):
        line = self._line(x, False)
        r = self.model.step(x, *self.args, *self.consts, self.lags, jacobian=False, line=line)[0] - self.target
        return r if self.w is None else self.w * r

    def jacobian(self, x):
        J = self._eval(x, jacobian=True)[1]
        return J if self.w is None else self.w[:, None] * J


#: Random start points of the baseline (§4.5.3's multi-start check), drawn in this order.
_RANDOM_STARTS = (
    ("c1", lambda rng: rng.uniform(4.0, 6.0)),  # V
    ("c2", lambda rng: np.exp(rng.uniform(np.log(0.3), np.log(5.0)))),
    ("c3", lambda rng: rng.uniform(-0.5, 1.0)),
    ("c4", lambda rng: rng.normal(0.0, 5.0)),
    ("c5", lambda rng: rng.normal(0.0, 1.0)),
    ("c7", lambda rng: np.exp(rng.uniform(np.log(2.0), np.log(100.0)))),
    ("c8", lambda rng: rng.uniform(-0.5, 0.5)),
    ("c9", lambda rng: np.exp(rng.uniform(np.log(0.01), np.log(0.5)))),
)


def start_points(
    n: int,
    bounds: tuple[np.ndarray, np.ndarray],
    rng: np.random.Generator,
    model: ChamberModel | None = None,
) -> np.ndarray:
    """Start vectors (n, P), by name: the model's start values (Table 4.1's for c1..c9, the extra
    terms' own), then seeded random ones for c1..c9 inside the bounds (extras keep their start)."""
    model = model or ChamberModel()
    lo, hi = bounds
    first = model.start()
    x0 = [np.clip(first, lo + 1e-6, hi - 1e-6)]
    i = model.index
    for _ in range(n - 1):
        x = first.copy()
        for name, draw in _RANDOM_STARTS:
            x[i[name]] = draw(rng)
        x[i["c6"]] = rng.uniform(0.5 * lo[i["c6"]], 0.5 * hi[i["c6"]])
        x0.append(np.clip(x, lo + 1e-6, hi - 1e-6))
    return np.array(x0)


def fit_chamber(
    data: ChamberData,
    options: FitOptions = FitOptions(),
    terms=(),
    rows: np.ndarray | None = None,
    start: ChamberParams | None = None,
    weights: np.ndarray | None = None,
    fixed: tuple = (),
) -> ChamberFit:
    """Fit c1..c9 of one chamber, and any extra ``terms``, by next-step least squares (§4.5.3).

    Parameters
    ----------
    terms : extra terms (:mod:`diegocal.pneumatic.terms`); their values are the start points
    rows : (T,) bool, the samples whose steps t -> t+1 may be used (both ends inside; the
        training blocks of a diagnosis); default every step
    start : a previous fit whose c1..c9 (and volume normalisation) start this one (default
        Table 4.1's start values and the data's own normalisation)
    weights : (T,) weight of the step from each sample (weighted least squares: the residual of
        step t -> t+1 is multiplied by ``weights[t]``); ``cost`` and ``rmse`` are then weighted too
    fixed : names of extra terms' parameters held at their values (standard error 0: what the
        data do not determine, such as a sensor lag beside a valve delay, is set by the caller)
    """
    if threadpool_limits is None:
        return _fit_chamber(data, options, terms, rows, start, weights, fixed)
    with threadpool_limits(limits=1, user_api="blas"):
        return _fit_chamber(data, options, terms, rows, start, weights, fixed)


def _fit_chamber(data, options, terms=(), rows=None, start=None, weights=None, fixed=()) -> ChamberFit:
    model = ChamberModel(terms)
    if start is not None:
        nominal = replace(start, terms=model.extra, stderr={})
    else:
        v_ref, v_scale = volume_normalisation(data.v if rows is None else data.v[np.asarray(rows, bool)])
        nominal = replace(
            ChamberParams.nominal(data.supply, data.room), v_ref=v_ref, v_scale=v_scale, terms=model.extra
        )
    problem = _Problem(data, nominal, model, rows, weights)
    lo, hi = model.lower(), model.upper()
    rng = np.random.default_rng(options.seed)
    starts = start_points(max(1, options.starts), (lo, hi), rng, model)
    if start is not None:
        n = len(P.NAMES)
        starts[0, :n] = np.clip(start.vector(), lo[:n] + 1e-6, hi[:n] - 1e-6)
    held = np.array([name in fixed for name in model.names])
    free = ~held
    x_held = model.start()  # the held parameters keep their terms' values

    def full(xf):
        x = x_held.copy()
        x[free] = xf
        return x

    if options.jacobian == "analytic":
        fun, jac = (lambda xf: problem.residuals(full(xf))), (lambda xf: problem.jacobian(full(xf))[:, free])
    elif options.jacobian == "2-point":
        fun, jac = (lambda xf: problem.residuals_only(full(xf))), "2-point"
    else:
        raise FitError(f"unknown jacobian {options.jacobian!r} (expected 'analytic' or '2-point')")
    lo, hi = lo[free], hi[free]

    def solve(x0):
        return least_squares(
            fun,
            x0,
            jac=jac,
            bounds=(lo, hi),
            method="trf",
            x_scale="jac",
            ftol=options.tol,
            xtol=options.tol,
            gtol=options.tol,
            max_nfev=options.max_nfev,
        )

    runs = []
    for x0 in starts[:, free]:
        try:
            res = solve(x0)
        except (ValueError, np.linalg.LinAlgError) as exc:
            raise FitError(f"chamber {data.name!r}: least squares failed ({exc})") from None
        runs.append(res)
    best = _hop_delays(min(runs, key=lambda r: r.cost), model, free, data, solve)
    if not np.isfinite(best.cost):
        raise FitError(f"chamber {data.name!r}: the fit diverged (non-finite cost)")
    n = problem.target.size
    x_best = full(best.x)
    J = problem.jacobian(x_best)
    clusters = _clusters(data, problem.rows)
    cov = np.zeros((model.n_params, model.n_params))
    cov[np.ix_(free, free)] = covariance(J[:, free], problem.residuals(x_best), clusters)
    stderr = np.sqrt(np.maximum(np.diag(cov), 0.0))
    fitted = nominal.from_vector(x_best, stderr)
    if options.drift_starts > 0:
        dr = drift(fitted, data, options.drift_starts, options.horizon_s)
        drift_2s, curve = dr.final, dr.curve()
    else:
        drift_2s, curve = float("nan"), []
    return ChamberFit(
        name=data.name,
        params=fitted,
        cost=float(best.cost),
        rmse=float(np.sqrt(2 * best.cost / n)),
        n_samples=int(n),
        nfev=int(best.nfev),
        drift_2s=drift_2s,
        drift_curve=curve,
        start_costs=tuple(float(r.cost) for r in runs),
        start_params=np.array([full(r.x) for r in runs]),
        covariance=cov,
        converged=bool(best.status > 0),  # 0: the evaluation budget ran out; -1: the solver failed
    )


#: The length of the contiguous blocks of steps of the cluster-robust covariance, s: longer than
#: the correlation time of the next-step residuals (the command's holds, 0.1-0.5 s), short
#: enough that a 30-s training set has tens of blocks.
SE_BLOCK_S = 1.0


#: Whole samples a fitted delay is moved by to restart the fit from (each sign): the step's cost
#: has a kink wherever the delay crosses a whole sample (the valve's command switches between two
#: lagged commands there), and a fit started within a sample of the truth can stop a sample away.
DELAY_HOPS = (1, 2)


def _hop_delays(best, model: ChamberModel, free: np.ndarray, data: ChamberData, solve):
    """The lowest-cost of ``best`` and the fits restarted from it with each free delay moved by
    DELAY_HOPS whole samples (inside its bounds); ``solve(x0)`` runs least squares on the free
    parameters."""
    at = [i for i in model.delay_at if free[i]]
    if not at:
        return best
    h = float(np.median(np.diff(data.time)))
    pos = np.cumsum(free) - 1  # index of a full parameter among the free ones
    lo, hi = model.lower()[free], model.upper()[free]
    out = best
    for i in at:
        for hop in DELAY_HOPS:
            for sign in (-1.0, 1.0):
                x0 = best.x.copy()
                x0[pos[i]] += sign * hop * h
                if not lo[pos[i]] < x0[pos[i]] < hi[pos[i]]:
                    continue
                try:
                    res = solve(x0)
                except (ValueError, np.linalg.LinAlgError):
                    continue
                if np.isfinite(res.cost) and res.cost < out.cost:
                    out = res
    return out


def _clusters(data: ChamberData, rows: np.ndarray) -> np.ndarray:
    """(n,) block labels of the fitted steps ``rows`` (indices t of steps t -> t+1): contiguous
    runs of rows cut into pieces of about :data:`SE_BLOCK_S` (never across a gap)."""
    mask = np.zeros(data.n_samples, bool)
    mask[rows] = True
    length = max(1, int(round(SE_BLOCK_S / float(np.median(np.diff(data.time))))))
    return sub_blocks(mask, length)[rows]


def covariance(J: np.ndarray, r: np.ndarray, clusters: np.ndarray) -> np.ndarray:
    """Cluster-robust (sandwich) covariance of a least-squares estimate, (P, P).

    .. math:: V = \\frac{G}{G-1} \\frac{n-1}{n-P} (J^T J)^{-1}
              \\Big(\\sum_g J_g^T r_g r_g^T J_g\\Big) (J^T J)^{-1}

    with J (n, P) the Jacobian of the residuals r (n,) at the estimate and g the ``clusters`` (n,)
    (contiguous blocks of time; CR1 small-sample factor). A variance is never below the
    model-based one, s² (JᵀJ)⁻¹ with s² = |r|² / (n - P): with tens of blocks the sandwich is
    itself uncertain and biased low, and independent residuals make the two equal (the matrix is
    rescaled, its correlations kept). Rows and columns of a direction the data do not determine (a
    singular value below 1e-12 of the largest) are NaN.
    """
    n, P = J.shape
    _, sv, vt = np.linalg.svd(J, full_matrices=False)
    keep = sv > sv[0] * 1e-12
    bread = (vt[keep].T / sv[keep] ** 2) @ vt[keep]
    labels, idx = np.unique(clusters, return_inverse=True)
    scores = np.zeros((labels.size, P))
    np.add.at(scores, idx, J * r[:, None])
    G = labels.size
    factor = G / max(G - 1, 1) * (n - 1) / max(n - P, 1)
    cov = factor * bread @ (scores.T @ scores) @ bread
    model = np.diag(bread) * float(r @ r) / max(n - P, 1)
    d = np.diag(cov)
    scale = np.sqrt(np.where(d > 0, np.maximum(model, d) / np.where(d > 0, d, 1.0), 1.0))
    cov = cov * scale[:, None] * scale[None, :]
    if (~keep).any():
        bad = np.abs(vt[~keep]).max(axis=0) > 1e-3
        cov[bad, :] = np.nan
        cov[:, bad] = np.nan
    return cov


@dataclass(frozen=True)
class BatchFit:
    """Fits of several chambers; ``skipped`` maps a chamber to why it was not fitted (one line)."""

    fits: dict
    skipped: dict


def _fit_task(args):
    data, options = args
    try:
        return data.name, fit_chamber(data, options), None
    except DiegocalError as exc:
        return data.name, None, str(exc)


def fit_chambers(
    datasets, options: FitOptions = FitOptions(), jobs: int = 1, progress=None
) -> BatchFit:
    """Fit independent chambers, in parallel processes when ``jobs > 1``.

    Parameters
    ----------
    datasets : iterable of ChamberData
    progress : optional callable(name) called as each chamber finishes
    """
    tasks = [(d, options) for d in datasets]
    fits, skipped = {}, {}

    def record(result):
        name, fit, err = result
        if fit is None:
            skipped[name] = err
        else:
            fits[name] = fit
        if progress is not None:
            progress(name)

    if jobs <= 1 or len(tasks) <= 1:
        for t in tasks:
            record(_fit_task(t))
    else:
        with ProcessPoolExecutor(max_workers=jobs) as pool:
            for result in pool.map(_fit_task, tasks):
                record(result)
    order = [d.name for d, _ in tasks]
    return BatchFit(
        {n: fits[n] for n in order if n in fits}, {n: skipped[n] for n in order if n in skipped}
    )
