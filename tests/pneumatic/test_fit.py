"""Next-step fit (thesis §4.5.3) and multi-step prediction (§4.5.4) against simulator truth."""

from dataclasses import replace

import numpy as np
import pytest

from diegocal.errors import FitError, LogFormatError, UnknownNameError
from diegocal.io import make_stream
from diegocal.pneumatic import FitOptions, chamber_data, drift, fit_chamber, fit_chambers
from diegocal.pneumatic.fit import volume_normalisation
from diegocal.pneumatic.params import NAMES, ChamberParams
from diegocal.pneumatic.predict import predict_with_resets
from diegocal.pneumatic.synthetic import simulate_model

TRUE_X = np.array([4.9, 1.5, 0.3, -20.0, 0.5, 0.3, 30.0, 0.1, 0.1])


def test_parametric_data_recovers_the_parameters_within_their_standard_errors(robot, train_log):
    # Identifiability: data made by the model itself (process noise 1 kPa) -> c1..c9 within 4 SE.
    name = "shoulder.flex"
    v = train_log.streams["pots"].column("shoulder_pot")
    v_ref, v_scale = volume_normalisation(v)
    truth = replace(ChamberParams.nominal(620.0, 100.0), v_ref=v_ref, v_scale=v_scale).from_vector(
        TRUE_X
    )
    log = simulate_model(train_log, robot.sensors, {name: truth}, noise=1.0, seed=3)
    assert ChamberParams.from_dict(log.truth.params["chambers"][name]).values["c7"] == 30.0
    fit = fit_chamber(chamber_data(log.without_truth(), robot.sensors, name))
    est, se = fit.params.vector(), np.array([fit.params.stderr[n] for n in NAMES])
    assert np.isfinite(se).all() and (se > 0).all()
    z = (est - TRUE_X) / se
    assert np.abs(z).max() < 4.0, dict(zip(NAMES, np.round(z, 2), strict=True))
    assert fit.rmse == pytest.approx(1.0, rel=0.05)  # residual = the injected process noise


def test_physics_fit_predicts_held_out_data_with_small_drift(robot, train_log, test_log):
    # §4.5.4 / Fig. 4.13: 2-s open-loop drift < 10 % of (Pc - Pr) on held-out data.
    datasets = [chamber_data(train_log, robot.sensors, n) for n in robot.sensors.chamber_names]
    batch = fit_chambers(datasets, FitOptions())
    assert set(batch.fits) == set(robot.sensors.chamber_names) and not batch.skipped
    for name, fit in batch.fits.items():
        held = chamber_data(test_log, robot.sensors, name)
        d = drift(fit.params, held)
        assert d.n_starts == 48 and d.horizon[-1] == pytest.approx(2.0)
        assert d.final < 0.10, (name, d.final)
        # the model beats "pressure stays where it was" by a wide margin
        pred = predict_with_resets(fit.params, held)
        hold = held.p[np.repeat(np.arange(0, held.n_samples, 200), 200)[: held.n_samples]]
        assert np.sqrt(np.mean((pred - held.p) ** 2)) < 0.5 * np.sqrt(np.mean((hold - held.p) ** 2))


def test_multi_start_converges_to_one_minimum(robot, train_log):
    # §4.5.3: "the optimization always converged to the same minimum, from different initial
    # conditions"
    fit = fit_chamber(
        chamber_data(train_log, robot.sensors, "elbow.ext"), FitOptions(starts=5, seed=1)
    )
    costs = np.array(fit.start_costs)
    assert costs.size == 5 and np.ptp(costs) / costs.min() < 1e-4
    spread = np.ptp(fit.start_params, axis=0)
    se = np.array([fit.params.stderr[n] for n in NAMES])
    assert (spread < 3 * se + 1e-6).all(), dict(zip(NAMES, spread / se, strict=True))


def test_analytic_and_finite_difference_jacobians_reach_the_same_fit(robot, train_log):
    data = chamber_data(train_log.slice(0, 2000), robot.sensors, "shoulder.ext")
    a = fit_chamber(data, FitOptions(jacobian="analytic"))
    b = fit_chamber(data, FitOptions(jacobian="2-point"))
    assert a.cost == pytest.approx(b.cost, rel=1e-4)


def test_bad_chamber_data_is_refused_clearly(robot, train_log):
    with pytest.raises(UnknownNameError, match="'knee.flex' is not in sensors.yaml"):
        chamber_data(train_log, robot.sensors, "knee.flex")
    flat = train_log.streams["pressure"].data.copy()
    flat[:, 0] = 350.0 + 0.1 * np.sin(np.arange(flat.shape[0]))
    log = train_log.with_streams(pressure=make_stream(train_log.streams["pressure"].names, flat))
    with pytest.raises(FitError, match="unidentifiable"):
        chamber_data(log, robot.sensors, robot.sensors.chamber_names[0])
    u = train_log.streams["valve"].data.copy()
    u[10, 1] = 11.0
    log = train_log.with_streams(valve=make_stream(train_log.streams["valve"].names, u))
    with pytest.raises(
        LogFormatError, match="11 V at sample 10 is outside the valve's range 0-10 V"
    ):
        chamber_data(log, robot.sensors, robot.sensors.chamber_names[1])
    with pytest.raises(FitError, match="at least"):
        chamber_data(train_log.slice(0, 20), robot.sensors, robot.sensors.chamber_names[1])


def test_block_standard_errors_widen_with_correlated_residuals_and_agree_with_independent_ones():
    from diegocal.pneumatic.fit import covariance

    rng = np.random.default_rng(2)
    n, blocks = 6000, np.repeat(np.arange(60), 100)
    J = np.column_stack([np.ones(n), rng.normal(size=n)])
    J[:, 1] = np.convolve(J[:, 1], np.ones(20) / 20, mode="same")  # a slowly varying regressor
    white = rng.normal(size=n)
    ar = np.zeros(n)
    for t in range(1, n):  # AR(1), correlation time ~ 20 samples
        ar[t] = 0.95 * ar[t - 1] + white[t]
    ols = lambda r: np.sqrt(np.diag(np.linalg.inv(J.T @ J)) * (r @ r) / (n - 2))  # noqa: E731
    se_white = np.sqrt(np.diag(covariance(J, white, blocks)))
    se_ar = np.sqrt(np.diag(covariance(J, ar, blocks)))
    assert np.all(se_white >= ols(white)) and np.all(se_white < 1.3 * ols(white))
    assert np.all(se_ar > 3.0 * ols(ar))  # the sandwich sees the correlation; s² (JᵀJ)⁻¹ does not
