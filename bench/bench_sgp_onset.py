"""Where the SGP's GP misleads: the onset of a friction region (issue #14, round 4).

    .venv/bin/python bench/bench_sgp_onset.py

Two cases of the 3-link arm with a hidden cable-like friction on joint 3 (``position_friction``,
active for q3 in a region), both tested on another trajectory of the same robot:

1. the scale bench's first 2,000 samples (bench_sgp_scale.py's log, 50 Hz): the guard's per-block
   cross-validated joint-3 nMSE of each candidate (why the SGP keeps PR there), and the test's
   joint-3 RMSE of PR and PRGP binned by q3 around the region's onset;
2. a 6-s run, `simulate dynamics --robot arm3 --effect position_friction:joint3 --duration 6
   --seed 11`, tested on `--seed 12 --robot-seed 11`'s trajectory: ±2σ coverage and RMSE of
   PR, PRGP and SGP binned by q3 (why the SGP's joint-3 coverage is low).

The region's bounds are read from the simulator's /truth to place the bins (evaluation only; no
fit reads them). Fits use the library's defaults.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/ is not installed
sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_sgp_case import simulate as simulate_case  # noqa: E402
from bench_sgp_scale import N_TEST, arrays, simulate  # noqa: E402

from diegocal.robot import BUNDLED_ROBOTS, load_robot  # noqa: E402
from diegocal.sgp import SGPOptions, fit_dynamics  # noqa: E402
from experiments.sgp.common import same_robot  # noqa: E402

KINDS = ("pr", "prgp", "sgp")


def onset_bins(low: float) -> list:
    """q3 bins (rad) around the region's lower bound ``low``."""
    edges = [-np.inf, low - 0.6, low - 0.3, low - 0.1, low, low + 0.2, np.inf]
    return list(zip(edges[:-1], edges[1:], strict=True))


def binned(q3, q3_train, measured, preds: dict, low: float) -> None:
    """Per q3 bin: test and training sample counts, RMSE (N·m) and ±2σ coverage per model."""
    head = "".join(f"{k + ' RMSE':>11}{k + ' ±2σ':>10}" for k in preds)
    print(f"{'q3 bin [rad]':<16}{'test n':>7}{'train n':>8}{head}")
    for a, b in onset_bins(low):
        mask = (q3 >= a) & (q3 < b)
        if not mask.any():
            continue
        cells = ""
        for tau, std in preds.values():
            err = measured[mask] - tau[mask]
            cells += f"{np.sqrt(np.mean(err**2)):11.4f}{np.mean(np.abs(err) <= 2 * std[mask]):10.2f}"
        n_train = int(((q3_train >= a) & (q3_train < b)).sum())
        print(f"[{a:5.2f}, {b:5.2f})  {int(mask.sum()):7d}{n_train:8d}{cells}")


def scale_case(robot) -> None:
    train = simulate(robot, 20000, seed=1).slice(0, 2000)
    test = simulate(robot, N_TEST, seed=2, friction=same_robot(train, robot))
    low = train.truth.effects[0]["region"]["low"]
    q, qd, qdd, tau = arrays(test, robot)
    print(f"== 1. scale bench, 2,000 samples; friction region starts at q3 = {low:.2f} rad")
    preds = {}
    for kind in KINDS:
        model = fit_dynamics(train, robot, SGPOptions(kind=kind))
        pred = model.predict_arrays(q, qd, qdd)
        preds[kind] = (pred.tau[:, 2], pred.tau_std[:, 2])
        if kind == "sgp":
            est = model.gp_
            print(f"guard's choice per joint: {est.selection_}; joint-3 nMSE × 1e3 per cross-validation block:")
            for label, blocks in est.validation_blocks_.items():
                print(f"  {label:<11}" + "".join(f"{1e3 * v:9.3f}" for v in blocks[:, 2]))
    binned(q[:, 2], train.stream("q").data[:, 2], tau[:, 2], preds, low)


def short_run(robot) -> None:
    train = simulate_case(robot, 11, duration=6.0)
    test = simulate_case(robot, 12, same_robot(train, robot), duration=6.0)
    low = train.truth.effects[0]["region"]["low"]
    measured = test.stream("tau").data[:, 2]
    print(f"\n== 2. 6-s run (seed 11), tested on seed 12's trajectory; region starts at q3 = {low:.2f} rad")
    preds = {}
    for kind in KINDS:
        pred = fit_dynamics(train, robot, SGPOptions(kind=kind)).predict(test)
        preds[kind] = (pred.tau[:, 2], pred.tau_std[:, 2])
    binned(test.stream("q").data[:, 2], train.stream("q").data[:, 2], measured, preds, low)


def main() -> int:
    sys.stdout.reconfigure(line_buffering=True)
    robot = load_robot(BUNDLED_ROBOTS / "arm3")
    scale_case(robot)
    short_run(robot)
    return 0


if __name__ == "__main__":
    sys.exit(main())
