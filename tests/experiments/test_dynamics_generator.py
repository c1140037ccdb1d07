"""The independent torque generator's sessions: another ``seed`` of one ``robot_seed`` is the same
robot (a user trial found its friction, noise and effect scaled with each session's motion)."""

import numpy as np
import pytest

from experiments.dynamics_generator import Session, generate


@pytest.mark.parametrize("hidden", ["position_friction", "hose", "cogging"])
def test_another_session_of_a_robot_has_its_friction_noise_and_effect(hidden):
    first = generate(Session(duration=8.0, seed=11, robot_seed=11, hidden=hidden, joint=1))
    second = generate(Session(duration=8.0, seed=12, robot_seed=11, hidden=hidden, joint=1))
    assert not np.allclose(first.streams["q"].data, second.streams["q"].data)  # another motion
    for key in ("viscous", "coulomb", "noise"):
        a, b = first.truth.params[key], second.truth.params[key]
        np.testing.assert_allclose([b[j] for j in a], list(a.values()), rtol=1e-12)
    (e1,), (e2,) = first.truth.effects, second.truth.effects
    assert e1.keys() == e2.keys() and e1["channel"] == e2["channel"]
    for k, v in e1.items():
        if isinstance(v, float):
            assert e2[k] == pytest.approx(v, rel=1e-12), k


def test_a_session_whose_seed_is_its_robots_is_drawn_on_its_own_motion():
    log = generate(Session(duration=8.0, seed=3, robot_seed=3, hidden="spring", joint=2))
    (effect,) = log.truth.effects
    q = log.streams["q"].data[:, 2]
    hidden = log.truth.signals["tau_hidden"].data[:, 2]
    noise = log.truth.params["noise"][log.streams["q"].names[2]]
    assert np.sqrt(np.mean(hidden**2)) == pytest.approx(6.0 * noise, rel=1e-9)  # sized: 6 × the noise, here
    assert effect["rest"] == pytest.approx(0.5 * (q.min() + q.max()))  # the middle of this session's range


def test_a_position_frictions_coefficients_are_the_robots_in_every_session():
    # a review: its viscous part was divided by each session's own velocity spread (0.71, 0.37, 0.46)
    slopes = []
    for seed in (0, 1, 2):
        log = generate(Session(robot="panda", duration=20.0, hidden="position_friction", joint=2, seed=seed,
                               robot_seed=0))
        qd = log.streams["qd"].data[:, 2]
        hidden = log.truth.signals["tau_hidden"].data[:, 2]
        inside = hidden != 0  # exactly c·sign(qd) + v·qd there: no noise in the truth
        A = np.column_stack([np.sign(qd[inside]), qd[inside]])
        slopes.append(np.linalg.lstsq(A, hidden[inside], rcond=None)[0])
    np.testing.assert_allclose(slopes, [slopes[0]] * 3, rtol=1e-6)
