"""Standard errors that cover the truth (issue #31): c1..c9 and a valve delay fitted on data made by
the model itself (process noise 1 kPa) on a few seeds; the bench (bench/bench_pneumatic_se.py)
measures the share within 2 SE on many, and on thin-plate valve delays."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import yaml

from diegocal.pneumatic import ChamberParams, FitOptions, chamber_data, fit_chamber
from diegocal.pneumatic.fit import volume_normalisation
from diegocal.pneumatic.synthetic import simulate_model
from diegocal.robot import load_robot
from diegocal.terms import make_term
from experiments import pneumatic_generator as gen

#: c1..c9 of a chamber of the generator's robot (a fit of a clean chamber).
X = np.array([5.05, 7.3, 375.0, -0.28, 0.05, 0.32, 76.8, 0.17, 0.045])


def _z(seed: int, delay: float | None):
    """z-scores (estimate - truth) / SE of c1..c9 and the delay on a 30-s log made by the model."""
    robot = load_robot(gen.ROBOT_DIR)
    log = gen.inputs(gen.GeneratorOptions(duration=30.0, seed=seed))
    v_ref, v_scale = volume_normalisation(log.stream("pots").column("elbow_pot"))
    truth = replace(ChamberParams.nominal(620.0, 100.0), v_ref=v_ref, v_scale=v_scale).from_vector(X)
    terms = () if delay is None else (make_term("valve_delay", "elbow.flex", {"delay_s": delay}),)
    truth = truth.with_terms(terms)
    log = simulate_model(log, robot.sensors, {"elbow.flex": truth}, noise=1.0, seed=seed)
    fit = fit_chamber(chamber_data(log.without_truth(), robot.sensors, "elbow.flex"), FitOptions(drift_starts=0),
                      terms=terms)
    se = np.array([fit.params.stderr[n] for n in fit.params.names()[:9]]
                  + [p.stderr for t in fit.params.terms for p in t.parameters])
    return (fit.params.full_vector() - truth.full_vector()) / se


def test_c1_to_c9_and_the_delay_lie_within_two_standard_errors_of_the_truth_on_most_seeds():
    z = [_z(seed, 0.031 if seed % 2 else None) for seed in range(6)]
    zc = np.abs(np.concatenate([x[:9] for x in z]))
    zd = np.abs([x[9] for x in z if x.size > 9])
    assert np.isfinite(zc).all() and zd.size == 3
    assert np.mean(zc <= 2.0) >= 0.85 and zc.max() < 4.5, np.round(zc, 2)
    assert (zd < 3.0).all(), zd


def test_a_delay_term_keeps_its_correlation_with_the_sensor_lag_and_files_without_it_still_load():
    base = ChamberParams.nominal(620.0, 100.0)
    delay = make_term("valve_delay", "c", {"delay_s": 0.03}, extra={"correlation": {"sensor_lag.lag_s": -0.9}})
    raw = yaml.safe_load(yaml.safe_dump(base.with_terms((delay,)).to_dict("c")))
    assert raw["terms"][0]["extra"]["correlation"] == {"sensor_lag.lag_s": -0.9}
    back = ChamberParams.from_dict(raw)
    assert back.terms[0].extra["correlation"]["sensor_lag.lag_s"] == -0.9
    del raw["terms"][0]["extra"]
    assert ChamberParams.from_dict(raw).terms[0].values[0] == 0.03


def test_a_delay_started_within_a_sample_of_the_truth_does_not_stop_a_sample_away():
    """Bench cases (bench_pneumatic_se, parametric) whose fitted delay stopped a whole 10-ms sample
    from the truth, 35-66 SE off, from a start 0-2 ms from it: the step's cost has a kink at every
    whole sample; the fit now restarts a sample or two either way and keeps the lower cost."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).parents[2] / "bench"))
    from bench_pneumatic_se import parametric_one

    for seed in (500_049, 500_055, 10_500_073):
        _, z_delay = parametric_one((seed, 60.0, True))
        assert abs(z_delay) < 3.0, (seed, z_delay)
