"""Thin-plate physics of thesis §4.2: eq. (4.1)-(4.4), (4.12)-(4.14)."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from diegocal.sim.pneumatics import _rate, _substep
from diegocal.sim.thin_plate import (
    GasConstants,
    ValveGeometry,
    flow_function,
    flow_function_and_derivatives,
    mass_flow,
    steady_state_pressure,
)

GAS = GasConstants()
VALVE = ValveGeometry(U_c=5.1, U_r=4.9, L_c=0.05e-6, L_r=0.05e-6, B=2e-6, smooth=1e-6)


def test_constants_match_table_4_2():
    assert GAS.theta == pytest.approx(1.8929, abs=1e-4)  # eq. (4.14) for kappa = 1.4
    # Choked flow of air through 1 mm² at 620 kPa: ~1.06 g/s (textbook value, C = 0.72)
    assert flow_function(620e3, 100e3) * 1e-6 == pytest.approx(1.06e-3, rel=0.01)


def test_flow_is_continuous_at_the_critical_ratio():
    # The printed eq. (4.13) would jump here; the module uses the continuous choked constant.
    pd = 100e3
    below, above = (
        flow_function(GAS.theta * pd * (1 - 1e-9), pd),
        flow_function(GAS.theta * pd * (1 + 1e-9), pd),
    )
    assert above == pytest.approx(below, rel=1e-6)


@pytest.mark.parametrize(
    "pu,pd", [(620e3, 150e3), (620e3, 400e3), (300e3, 250e3), (150e3, 400e3), (610e3, 620e3)]
)
def test_flow_derivatives_match_finite_differences(pu, pd):
    _, du, dd = flow_function_and_derivatives(pu, pd)
    e = 1.0
    assert du == pytest.approx(
        (flow_function(pu + e, pd) - flow_function(pu - e, pd)) / (2 * e), rel=1e-5
    )
    assert dd == pytest.approx(
        (flow_function(pu, pd + e) - flow_function(pu, pd - e)) / (2 * e), rel=1e-5
    )


def test_flow_is_antisymmetric_and_zero_at_equal_pressure():
    assert flow_function(300e3, 500e3) == pytest.approx(-flow_function(500e3, 300e3))
    assert flow_function(300e3, 300e3) == 0.0


def test_two_port_flow_decreases_with_pressure_and_steady_state_is_its_root():
    # Fig. 4.4: m_dot(p) is monotonically decreasing; p_ss solves m_dot = 0 (§4.3.1).
    u = np.array([3.5, 4.9, 5.0, 5.2, 6.5])
    a_c, a_r = VALVE.areas(u)
    p = np.linspace(100e3, 620e3, 200)[:, None]
    m, _ = mass_flow(p, a_c, a_r, 620e3, 100e3)
    assert (np.diff(m, axis=0) < 0).all()
    pss = steady_state_pressure(u, VALVE, 620e3, 100e3)
    assert np.abs(mass_flow(pss, a_c, a_r, 620e3, 100e3)[0]).max() < 1e-9
    assert (np.diff(pss) > 0).all() and pss[0] < 150e3 and pss[-1] > 600e3  # sigmoid, Fig. 4.7


def test_valve_areas_follow_eq_4_3():
    a_c, a_r = VALVE.areas(np.array([3.0, 5.0, 7.0]))
    # sealed port: the leakage area plus the smooth max's tail (w² / (4 |x|) for x << 0)
    assert VALVE.L_c < a_c[0] < VALVE.L_c + 0.1e-6 and VALVE.L_r < a_r[2] < VALVE.L_r + 0.1e-6
    assert a_c[2] == pytest.approx((7.0 - 5.1) * VALVE.B, rel=0.05)
    assert a_r[0] == pytest.approx((4.9 - 3.0) * VALVE.B, rel=0.05)


def test_exponential_midpoint_step_agrees_with_radau():
    # One small, moving chamber through a discharge and a charge (stiff: tau ~ 1 ms);
    # the simulator's sub-step (0.5 ms) against a tight Radau solution of eq. (4.4).
    def vol(t):
        return 3e-6 + 2e-6 * np.sin(8 * t), 16e-6 * np.cos(8 * t)

    def areas(t):
        return VALVE.areas(np.array([6.5 if t < 0.05 else 3.5]))

    def f(t, p):
        v, vd = vol(t)
        a_c, a_r = areas(t)
        return _rate(np.atleast_1d(p), a_c, a_r, 620e3, 100e3, v, vd, GAS)[0]

    ref = solve_ivp(
        f,
        (0, 0.1),
        [100e3],
        method="Radau",
        rtol=1e-10,
        atol=1e-6,
        max_step=1e-3,
        t_eval=np.arange(1, 21) * 0.005,
    )
    dt, p, out = 5e-4, np.array([100e3]), []
    for k in range(200):
        t = k * dt
        a_c, a_r = areas(t)
        v, vd = vol(t + dt / 2)
        p, _, _ = _substep(p, a_c, a_r, 620e3, 100e3, v, vd, dt, GAS)
        if (k + 1) % 10 == 0:
            out.append(p[0])
    assert np.abs(np.array(out) - ref.y[0]).max() < 1e3  # < 1 kPa over a 520 kPa swing
