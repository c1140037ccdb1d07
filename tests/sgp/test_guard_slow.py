"""The guard against the GP soaking up physics (slow: `make bench` runs it).

Thesis §3.4.2 forward model of the reaction wheel, eq. (3.28): accelerations from
[sin θ_p, θ_w, m] per axis, 6 parameters, while the simulator also has viscous friction.
Trained on pole-down data, tested on pole-up (LQR-balanced) data. Without the guard a plain
ML-II SGP may let the GP take over the motor term of the wheel axis (w₆ → 0) and fail pole-up;
with the guard (GP on the state only, not on m; flat prior on W; σ_z prior and bound at the
parametric residual; validation-judged starts) it must not.
"""

import numpy as np
import pytest

from diegocal.robot import BUNDLED_ROBOTS, load_robot
from diegocal.sgp import DEFAULT_GUARD, SemiParametricGP, SquaredExponential, Subspace, nmse

pytestmark = pytest.mark.slow


def _forward(log):
    q, qd, qdd, tau = (log.stream(s).data for s in ("q", "qd", "qdd", "tau"))
    m = tau[:, 1]  # the wheel motor's torque plays the thesis's control signal m
    row = np.column_stack([np.sin(q[:, 0]), q[:, 1], m])
    F = np.zeros((len(q), 2, 6))
    F[:, 0, :3], F[:, 1, 3:] = row, row
    return np.column_stack([q, qd, m]), qdd, F


def _sim(trajectory, seed, duration):
    from diegocal.sim.dynamics import DynamicsOptions, simulate_dynamics

    robot = load_robot(BUNDLED_ROBOTS / "reaction_wheel")
    opts = DynamicsOptions(duration=duration, trajectory=trajectory)
    return simulate_dynamics(robot, opts, np.random.default_rng(seed)).without_truth()


@pytest.mark.parametrize("seed", [2, 5])
def test_guard_keeps_the_motor_term_in_the_parametric_part(seed):
    U, Y, F = _forward(_sim("pole-down", seed, 10.0))
    U, Y, F = U[::2], Y[::2], F[::2]
    Uu, Yu, Fu = _forward(_sim("pole-up", seed + 200, 5.0))
    pr = SemiParametricGP([None, None], seed=seed).fit(U, Y, F)
    kernels = [Subspace([0, 1, 2, 3], SquaredExponential(4)) for _ in range(2)]  # not on m
    guarded = SemiParametricGP(kernels, seed=seed, restarts=1, guard=DEFAULT_GUARD).fit(U, Y, F)
    e_pr = nmse(pr.predict(Uu, Fu)[0], Yu)
    e_guard = nmse(guarded.predict(Uu, Fu)[0], Yu)
    # the wheel axis pole-up: no worse than the parametric model, and the motor gain is kept
    assert e_guard[1] < 1.5 * e_pr[1] + 0.01, (e_pr, e_guard)
    assert abs(guarded.w_[5] - pr.w_[5]) < 0.2 * abs(pr.w_[5])
