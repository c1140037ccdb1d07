"""Multi-step prediction of chamber pressure from measured u, v, vdot (thesis §4.5.4, Fig. 4.12/13).

The model alone integrates the pressure: p̂_0 = p_0, p̂_{t+h} = p̂_{t+h}(p̂_t, u_t, v_t, vdot_t; c)
by the exact step (4.7); the prediction is free to drift from the measurement.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from diegocal.errors import FitError
from diegocal.pneumatic.data import ChamberData
from diegocal.pneumatic.model import ChamberModel, LineState, model_of
from diegocal.pneumatic.params import ChamberParams

#: Fig. 4.13: 48 start points per chamber, 2 s horizon.
N_STARTS = 48
HORIZON_S = 2.0
#: The step (s of horizon) of the drift curves written to result files.
CURVE_STEP_S = 0.1


@dataclass(frozen=True)
class Drift:
    """Prediction error against horizon for one chamber (thesis Fig. 4.13).

    Attributes
    ----------
    horizon : (H+1,) s, time since the last measured pressure
    rms : (H+1,) pressure unit, root-mean-square error over the start points
        (the thesis's "standard deviation of the prediction error"; RMS also counts any bias)
    span : P_c - P_r in the pressure unit; ``rms / span`` is the drift as a fraction of it
    n_starts : number of start points used
    """

    horizon: np.ndarray
    rms: np.ndarray
    span: float
    n_starts: int

    @property
    def final(self) -> float:
        """RMS error at the full horizon as a fraction of P_c - P_r (0.1 is the thesis's 10 %)."""
        return float(self.rms[-1] / self.span)

    def curve(self, step_s: float = CURVE_STEP_S) -> list[float]:
        """The fraction-of-span curve at every ``step_s`` of horizon (s), whatever the sample rate
        (for result files, whose ``curve_step_s`` says the step)."""
        at = np.arange(0.0, float(self.horizon[-1]) + 1e-9, step_s)
        idx = np.unique(np.clip(np.searchsorted(self.horizon, at - 1e-9), 0, self.horizon.size - 1))
        return [float(x) for x in (self.rms / self.span)[idx]]


def line_state(model: ChamberModel, x, params: ChamberParams, data: ChamberData, rows=None, jacobian=False):
    """The supply hose's sag (:meth:`~diegocal.pneumatic.model.ChamberModel.line`) along every step
    t -> t+1 of ``data`` (T-1 steps), driven by the measured pressure (an observer of the hose; None
    for a model without one). The hose starts at its equilibrium at the log's start, after each gap
    and, when ``rows`` (T,) bool is given, at each step that follows one outside them (a block
    edge: the sag of the fitted rows never reads the pressure of rows outside them); ``x`` the
    model's packed vector, ``params`` its volume normalisation and constants."""
    if model.hose is None:
        return None
    ok = data.steps.copy()
    if rows is not None:
        rows = np.asarray(rows, bool)
        ok &= rows[:-1] & rows[1:]
    reset = np.concatenate([[True], ~ok[:-1]])
    v, vd = params.volume_coordinate(data.v[:-1], data.vd[:-1])
    consts = (params.c_b, params.c_s, params.c_gamma)
    return model.line(x, data.p[:-1], data.u[:-1], v, vd, data.h, *consts, reset, jacobian)


def integrate_from(params: ChamberParams, data: ChamberData, starts, n_steps: int) -> np.ndarray:
    """Open-loop pressure from each start index for ``n_steps`` steps, vectorised over starts.
    A supply hose starts from the sag its observer (:func:`line_state`) gives at the start, as the
    pressure starts from the measured one, and is stepped with the predicted pressure.

    Parameters
    ----------
    starts : (S,) int sample indices with starts + n_steps < T

    Returns
    -------
    (S, n_steps + 1) predicted pressure; column 0 is the measured p at the starts.
    """
    starts = np.asarray(starts, dtype=int)
    model = model_of(params)
    x = params.full_vector()
    h = np.diff(data.time)
    v, vd = params.volume_coordinate(data.v, data.vd)
    lags = data.u_lags(model.n_lags(float(np.median(h)))) if model.has_delay else None
    out = np.empty((starts.size, n_steps + 1))
    out[:, 0] = data.p[starts]
    hose = line_state(model, x, params, data)
    sag = None if hose is None else hose.start[starts]
    consts = (params.c_b, params.c_s, params.c_gamma)
    for j in range(n_steps):
        i = starts + j
        line = None
        if sag is not None:
            mean, sag = model.line_step(x, sag, out[:, j], data.u[i], v[i], vd[i], h[i], *consts)
            line = LineState(mean, sag)
        out[:, j + 1] = model.step(
            x,
            out[:, j],
            data.u[i],
            v[i],
            vd[i],
            h[i],
            params.c_b,
            params.c_s,
            params.c_gamma,
            None if lags is None else lags[i],
            jacobian=False,
            line=line,
        )[0]
    return out


def next_step(params: ChamberParams, data: ChamberData) -> np.ndarray:
    """(T - 1,) the model's p̂_{t+1} from the measured p_t, u_t, v_t, vdot_t (the fit's target;
    thesis Fig. 4.11); steps across a gap in the recording are predicted all the same."""
    model = model_of(params)
    h = np.diff(data.time)
    v, vd = params.volume_coordinate(data.v[:-1], data.vd[:-1])
    lags = data.u_lags(model.n_lags(float(np.median(h))))[:-1] if model.has_delay else None
    x = params.full_vector()
    consts = (params.c_b, params.c_s, params.c_gamma)
    line = line_state(model, x, params, data)
    return model.step(x, data.p[:-1], data.u[:-1], v, vd, h, *consts, lags, jacobian=False, line=line)[0]


def horizon_steps(data: ChamberData, horizon_s: float) -> int:
    return max(1, int(round(horizon_s / float(np.median(np.diff(data.time))))))


def drift(
    params: ChamberParams, data: ChamberData, n_starts: int = N_STARTS, horizon_s: float = HORIZON_S
) -> Drift:
    """RMS error of open-loop prediction against horizon from ``n_starts`` evenly spaced starts."""
    n = horizon_steps(data, horizon_s)
    if data.n_samples < n + 2:
        raise FitError(
            f"chamber {data.name!r}: the log ({data.n_samples} samples) is shorter than "
            f"the {horizon_s:g} s prediction horizon"
        )
    ok = _clear_starts(data, n)
    if ok.size == 0:
        raise FitError(
            f"chamber {data.name!r}: no gap-free stretch of the log is {horizon_s:g} s long"
        )
    starts = np.unique(ok[np.linspace(0, ok.size - 1, n_starts).astype(int)])
    pred = integrate_from(params, data, starts, n)
    err = pred - data.p[starts[:, None] + np.arange(n + 1)]
    rms = np.sqrt(np.mean(err**2, axis=0))
    return Drift(
        np.arange(n + 1) * float(np.median(np.diff(data.time))),
        rms,
        float(data.supply - data.room),
        int(starts.size),
    )


def _clear_starts(data: ChamberData, n: int) -> np.ndarray:
    """Start indices whose next n steps stay inside one gap-free stretch of the log."""
    bad = np.concatenate([~data.steps, np.ones(n, bool)])  # the log's end counts as a gap
    window = np.convolve(
        bad.astype(float), np.ones(n), mode="valid"
    )  # (T,): gaps in steps s..s+n-1
    return np.flatnonzero(window < 0.5)


def reset_starts(data: ChamberData, horizon_s: float = HORIZON_S) -> np.ndarray:
    """(R,) sample indices where :func:`predict_with_resets` re-initialises the prediction with the
    measured pressure: every ``horizon_s``, restarted at each gap between sessions."""
    n, last = horizon_steps(data, horizon_s), data.n_samples - 1
    seg = np.append(data.segment_starts(), data.n_samples)
    starts = np.concatenate([np.arange(a, b, n) for a, b in zip(seg[:-1], seg[1:], strict=True)])
    return starts[starts < last] if (starts < last).any() else starts[:1]


def predict_with_resets(
    params: ChamberParams, data: ChamberData, horizon_s: float = HORIZON_S
) -> np.ndarray:
    """Pressure predicted open loop and re-initialised to the measurement every ``horizon_s``
    (the dotted grid lines of thesis Fig. 4.12); shape (T,)."""
    n = horizon_steps(data, horizon_s)
    T = data.n_samples
    starts = reset_starts(data, horizon_s)
    # Segments run n steps; the last one may be shorter: pad the inputs by repeating the end.
    pad = starts[-1] + n - (T - 1)
    padded = data
    if pad > 0:
        ext = np.arange(T, T + pad)
        dt = float(np.median(np.diff(data.time)))
        idx = np.minimum(np.arange(T + pad), T - 1)
        padded = ChamberData(
            data.name,
            np.concatenate([data.time, data.time[-1] + dt * (ext - T + 1)]),
            data.u[idx],
            data.p[idx],
            data.v[idx],
            data.vd[idx],
            data.supply,
            data.room,
        )
    pred = integrate_from(params, padded, starts, n)  # (S, n+1)
    out = np.empty(T)
    ends = np.append(starts[1:], T)
    for k, (a, b) in enumerate(zip(starts, ends, strict=True)):
        out[a:b] = pred[k, : b - a]
    return out


def drift_summary(drifts) -> dict:
    """The pneumatic fits' 2-s drift (thesis §4.5.3, a fraction of Pc - Pr per chamber) in four
    numbers: ``median``, ``max``, and how many chambers stay ``below 4 %`` and ``below 10 %``."""
    v = np.asarray(list(drifts), float)
    return {
        "median": float(np.median(v)) if v.size else float("nan"),
        "max": float(v.max()) if v.size else float("nan"),
        "below 4 %": int((v < 0.04).sum()),
        "below 10 %": int((v < 0.10).sum()),
    }
