"""transmission_backlash in the dynamics model: the play operator, and a model whose columns are
evaluated at the link angle (issue #31)."""

from __future__ import annotations

import numpy as np
import pytest

from diegocal.errors import MissingStreamError
from diegocal.robot import load_robot
from diegocal.robot.model import BUNDLED_ROBOTS
from diegocal.sgp import SGPOptions, load_model
from diegocal.sgp.backlash import link_angles, play
from diegocal.sgp.model import DynamicsModel
from diegocal.sgp.store import save_model
from diegocal.sim.dynamics import DynamicsOptions, simulate_dynamics
from diegocal.sim.kinematic_effects import backlash
from diegocal.terms import make_term


@pytest.fixture(scope="module")
def arm3():
    return load_robot(BUNDLED_ROBOTS / "arm3")


def test_play_follows_the_motor_a_half_width_behind_and_restarts_at_a_gap():
    time = np.arange(400) * 0.01
    x = 0.3 * np.sin(2 * np.pi * 0.4 * time) + 0.05 * np.sin(2 * np.pi * 2.1 * time)
    y = play(x, time, 0.05)
    assert y[0] == x[0] and np.all(np.abs(y - x) <= 0.05 + 1e-15)
    assert np.any(np.isclose(np.abs(y - x), 0.05))  # engaged on either side once the motor has moved
    # two routes: the simulators' play operator (a dead band of twice the half-width)
    np.testing.assert_array_equal(y, backlash(x, 0.1))
    gap = time.copy()
    gap[200:] += 1.0  # a gap: the play starts again centred on the motor's angle
    y2 = play(x, gap, 0.05)
    assert y2[200] == x[200] and np.array_equal(y2[:200], y[:200])
    np.testing.assert_array_equal(play(x, time, 0.0), x)


@pytest.mark.parametrize("n", [2, 3, 1000, 4097])
def test_play_equals_the_recursion_sample_by_sample(n):
    x = np.cumsum(np.random.default_rng(n).standard_normal(n)) * 0.02
    y, link = play(x, None, 0.03), float(x[0])
    for t in range(n):  # y_t = clamp(y_{t-1}, x_t - b, x_t + b), one sample at a time
        link = min(max(link, x[t] - 0.03), x[t] + 0.03)
        assert y[t] == link


def test_a_backlash_model_predicts_with_the_link_angle_and_needs_the_time(arm3, tmp_path):
    """Held at the simulator's half-width, the model's columns at the link angle fit the torque
    to the noise; the same model without the backlash misses it several times over."""
    opts = DynamicsOptions(duration=10.0, effects=("transmission_backlash:joint2=0.03",), noise=0.01)
    log = simulate_dynamics(arm3, opts, np.random.default_rng(4))
    q, qd, qdd, tau = (log.stream(s).data for s in ("q", "qd", "qdd", "tau"))
    term = make_term("transmission_backlash", "joint2", {"half_width": 0.03})
    model = DynamicsModel(arm3, SGPOptions(kind="pr"), terms=(term,)).fit_arrays(q, qd, qdd, tau, time=log.time)
    assert model.parameter_names == tuple(model.base_.names)  # no columns of its own
    assert model.fitted_terms()[0].value("half_width") == 0.03  # held as given
    pred = model.predict_arrays(q, qd, qdd, log.time).tau
    assert np.sqrt(np.mean((pred - tau) ** 2)) < 0.0115
    # every column at the link angle: the features are the plain model's at play(q_j, b)
    plain = DynamicsModel(arm3, SGPOptions(kind="pr")).fit_arrays(q, qd, qdd, tau)
    moved = link_angles((term,), arm3, q, log.time)
    np.testing.assert_allclose(model.features(q, qd, qdd, log.time), plain.features(moved, qd, qdd), atol=1e-12)
    assert np.sqrt(np.mean((plain.predict_arrays(q, qd, qdd).tau - tau) ** 2)) > 2 * 0.0115
    np.testing.assert_allclose(model.mean_in_chunks(q, qd, qdd, log.time), pred, atol=1e-9)
    save_model(model, tmp_path / "b.sgp", {"log": "x"})
    np.testing.assert_allclose(load_model(tmp_path / "b.sgp").predict_arrays(q, qd, qdd, log.time).tau, pred, atol=1e-9)
    with pytest.raises(MissingStreamError, match="time"):
        DynamicsModel(arm3, SGPOptions(kind="pr"), terms=(term,)).fit_arrays(q, qd, qdd, tau)
