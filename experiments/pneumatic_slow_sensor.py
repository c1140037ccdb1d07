"""Does an open-loop score tell a slow pressure sensor from the causes that stand in for it?
(issue #31: the slow sensor of :mod:`experiments.pneumatic_oov` is named ``supply_droop`` or
``valve_delay``; a rival judged on one-step residuals could not tell it from a true sag.)

For one chamber it prints the held-out open-loop RMSE (the last 30 % of the log, contiguous;
predictions reset to the measurement every 2 s, as ``diagnose`` scores) of the baseline, the
baseline with a ``supply_droop`` of each shape and with a ``valve_delay``, and of a filtered-sensor
model for τ on a grid: the baseline fitted on the filter-inverted pressure y + τ ẏ (ẏ a central
difference), its open-loop pressure passed through the filter from each reset (the reading's exact
answer to a ramp), each as a ratio to the baseline's. The experiment that led to the diagnosis's
rival (diegocal/diagnose/pneumatics_filter.py, which picks τ on the training rows instead):

    python experiments/pneumatic_slow_sensor.py slow 777 778
    python experiments/pneumatic_slow_sensor.py supply_droop 2685631677
"""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from diegocal.diagnose import DiagnoseOptions  # noqa: E402
from diegocal.diagnose.pneumatics import PneumaticAdapter, adapters  # noqa: E402
from diegocal.diagnose.pneumatics_filter import FILTER_TAUS_S, through_filter  # noqa: E402
from diegocal.pneumatic.predict import predict_with_resets, reset_starts  # noqa: E402
from diegocal.terms import make_term  # noqa: E402


def ratios(log, robot, chamber: str) -> dict:
    """{model: held-out open-loop RMSE / the baseline's} (the module docstring), and the baseline's."""
    (adapter,) = adapters(log, robot, DiagnoseOptions(domain="pneumatics", chambers=(chamber,)))
    data = adapter.data
    train = np.arange(data.n_samples) < int(0.7 * data.n_samples)
    held = ~train
    held[-1] = False
    y = data.p.astype(float)

    def rmse(pred):
        return float(np.sqrt(np.nanmean((pred[held] - y[held]) ** 2)))

    out = {"baseline": rmse(predict_with_resets(adapter.fit((), train).params, data))}
    terms = {
        f"droop {e.get('shape', 'lasting')}": make_term("supply_droop", chamber, {"droop": 1.0}, extra=e)
        for e in ({}, {"shape": "flow"}, {"shape": "orifice"})
    }
    terms["delay"] = make_term("valve_delay", chamber, {"delay_s": 0.03})
    for name, term in terms.items():
        out[name] = rmse(predict_with_resets(adapter.fit((term,), train).params, data))
    starts = reset_starts(data)
    for tau in FILTER_TAUS_S:
        inverted = replace(data, p=y + tau * np.gradient(y, data.time))
        fit = PneumaticAdapter(inverted, adapter.volume_sensor).fit((), train)
        pressure = predict_with_resets(fit.params, inverted)
        out[f"filter {tau * 1e3:.0f} ms"] = rmse(through_filter(pressure, y, starts, data.time, tau))
    base = out["baseline"]
    return {k: v / base for k, v in out.items()} | {"baseline kPa": base}


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    kind, seeds = argv[0], [int(s) for s in argv[1:]]
    for seed in seeds:
        if kind == "slow":
            from diegocal.robot import load_robot
            from experiments import pneumatic_generator as gen
            from experiments.pneumatic_oov import add_shape

            log, chamber, _ = add_shape("slow_sensor", seed)
            robot = load_robot(gen.ROBOT_DIR)
        else:
            from bench_diagnose import simulate

            log, robot = simulate("pneumatics", kind, seed)
            chamber = log.truth.effects[0]["channel"]
        r = ratios(log.without_truth(), robot, chamber)
        print(kind, seed, chamber, " ".join(f"{k} {v:.3g}" for k, v in r.items()), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
