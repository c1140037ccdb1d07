"""Logs made by the parametric model itself (identifiability tests of the fit and of diagnose).

The thin-plate physics that stands for a real robot is the simulator's (``diegocal.sim``); this
module replaces a log's pressures by what the valve-chamber model of thesis eq. (4.10), with any
extra terms, predicts from its own previous output: data whose true parameters are known exactly.
"""

from __future__ import annotations

import numpy as np

from diegocal.io import Log, Truth, make_stream
from diegocal.pneumatic.data import chamber_data
from diegocal.pneumatic.model import LineState, model_of


def simulate_model(log: Log, sensors, params: dict, noise: float, seed: int) -> Log:
    """Replace the log's pressure by the 9-parameter model's own output (identifiability tests).

    p_{t+1} = step(p_t, u_t, v_t, vdot_t; c) + N(0, noise²) (thesis eq. 4.7) from room pressure,
    with u, v (the volume sensors) and vdot (their forward difference) taken from ``log``.
    ``params`` maps chamber names to :class:`~diegocal.pneumatic.params.ChamberParams` (with any
    extra terms); other chambers are dropped. /truth records them in the pneumatic.yaml schema.
    """
    rng = np.random.default_rng(seed)
    names = list(params)
    out = np.empty((log.n_samples, len(names)))
    for k, name in enumerate(names):
        d = chamber_data(log, sensors, name, check_span=False)
        c = params[name]
        p = out[:, k]
        p[0] = d.room
        h = np.diff(d.time)
        eps = rng.normal(0.0, noise, d.n_samples)
        model = model_of(c)
        lags = d.u_lags(model.n_lags(float(np.median(h))))
        x, consts = c.full_vector(), (c.c_b, c.c_s, c.c_gamma)
        v, vd = c.volume_coordinate(d.v, d.vd)
        sag, line = None, None  # a supply hose, from its equilibrium
        if model.hose is not None:
            sag = model.line(x, p[:1], d.u[:1], v[:1], vd[:1], h[:1], *consts).start[0]
        for t in range(d.n_samples - 1):  # p_{t+1} = step(p_t, ...) + noise (eq. 4.7)
            if sag is not None:
                mean, sag = model.line_step(x, sag, p[t], d.u[t], v[t], vd[t], h[t], *consts)
                line = LineState(mean, sag)
            p[t + 1] = model.step(x, p[t], d.u[t], v[t], vd[t], h[t], *consts, lags[t], False, line)[0] + eps[t]
    truth = Truth(
        params={"model": "parametric", "chambers": {n: params[n].to_dict(n) for n in names}},
        effects=[],
        signals=dict(log.truth.signals) if log.truth else {},
    )
    streams = dict(log.streams)
    streams["pressure"] = make_stream(names, out)
    streams["valve"] = log.streams["valve"].select(names)
    return Log(log.time, streams, robot=log.robot, rate_hz=log.rate_hz, truth=truth)
