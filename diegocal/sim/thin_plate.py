"""The physical valve-chamber model of thesis §4.2: thin-plate ports, proportional valves, chambers.

Units are SI throughout this module: pressure in Pa (absolute), area in m², volume in m³,
mass flow in kg/s, time in s. The simulator (``diegocal.sim.pneumatics``) converts to the
log's kPa at its boundary. The fitting code never uses this module: the parametric model of
§4.4 (``diegocal.pneumatic.model``) is fitted to data only.

Departures from the printed thesis, each needed for the model to be what the text says:

* eq. (4.13): the printed ``beta = C sqrt(kappa M / (Z R T)) (2/(kappa+1))^((kappa+1)/(kappa-1))``
  puts the exponent outside the square root, which makes ``z`` jump at ``p_u/p_d = theta``
  although the text says the flow function is continuously differentiable. The standard choked
  flow constant (exponent inside the root, i.e. halved) is continuous there; we use it.
* eq. (4.4a): ``kappa R T / v * m_dot`` needs the molar mass to be dimensionally right with R in
  J/(mol K): we use the specific gas constant ``R / M``.
* eq. (4.1c) has an infinite slope at p_u = p_d (z ~ sqrt(p_u - p_d)), which makes any
  integrator overshoot there. Like laminar-flow corrections of orifice models (ISO 6358), we
  continue z linearly in p_d for p_d / p_u > 0.99 (value-continuous; it changes flows only
  within 1 % of equal pressures). Set ``X_LAMINAR = 1`` to remove it.
* eq. (4.3): ``smax`` is applied to an area, so it needs an area scale; we write
  ``smax_w(x) = w * smax(x / w)`` with ``w`` = :attr:`ValveGeometry.smooth` (m²).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# Table 4.2 (air).
M_AIR = 0.029  # kg/mol
R_GAS = 8.31  # Pa m^3 / (mol K)
C_DISCHARGE = 0.72
Z_AIR = 0.99
KAPPA = 1.4
T_ROOM = 293.15  # K (the thesis leaves T unspecified; room temperature)


#: Pressure ratio p_d / p_u above which the flow is continued linearly (see module doc).
X_LAMINAR = 0.99
W_LAMINAR = float(np.sqrt(X_LAMINAR ** (2 / KAPPA) - X_LAMINAR ** ((KAPPA + 1) / KAPPA)))


@dataclass(frozen=True)
class GasConstants:
    """Constants of the thin-plate port (thesis Table 4.2) and the derived eq. (4.12-4.14)."""

    M: float = M_AIR
    R: float = R_GAS
    T: float = T_ROOM
    C: float = C_DISCHARGE
    Z: float = Z_AIR
    kappa: float = KAPPA

    def __post_init__(self):
        k = self.kappa
        den = self.Z * self.R * self.T
        # Thesis eq. (4.12)-(4.14), computed once (the simulator evaluates them per sub-step).
        object.__setattr__(self, "_alpha", self.C * np.sqrt(2.0 * self.M / den * k / (k - 1.0)))
        object.__setattr__(
            self,
            "_beta",
            self.C * np.sqrt(k * self.M / den * (2.0 / (k + 1.0)) ** ((k + 1.0) / (k - 1.0))),
        )
        object.__setattr__(self, "_theta", ((k + 1.0) / 2.0) ** (k / (k - 1.0)))

    @property
    def alpha(self) -> float:
        """Thesis eq. (4.12), s/m."""
        return self._alpha

    @property
    def beta(self) -> float:
        """Choked-flow constant, s/m: eq. (4.13) with the exponent inside the root (module doc)."""
        return self._beta

    @property
    def theta(self) -> float:
        """Critical pressure ratio, thesis eq. (4.14)."""
        return self._theta

    @property
    def rt_over_m(self) -> float:
        """Specific gas constant times temperature, R T / M in J/kg."""
        return self.R * self.T / self.M

    def to_dict(self) -> dict:
        return {
            "M": self.M,
            "R": self.R,
            "T": self.T,
            "C": self.C,
            "Z": self.Z,
            "kappa": self.kappa,
            "alpha": self.alpha,
            "beta": self.beta,
            "theta": self.theta,
        }


def z_flow(pu, pd, gas: GasConstants):
    """z(p_u, p_d) of thesis eq. (4.1c) for p_u >= p_d, with its partial derivatives.

    Returns (z, dz/dp_u, dz/dp_d); arrays broadcast together; kg/(s m²) and kg/(s m² Pa).
    """
    k = gas.kappa
    a, b = 2.0 / k, (k + 1.0) / k
    alpha, beta, theta = gas.alpha, gas.beta, gas.theta
    pu = np.maximum(pu, 1e-9)
    x = np.minimum(pd / pu, 1.0)
    choked = x < 1.0 / theta  # p_u / p_d > theta
    xs = np.maximum(x, 1.0 / theta)  # keep the subsonic branch finite where unused
    xa = xs**a
    xb = xa * xs ** (b - a)
    w = np.sqrt(np.maximum(xa - xb, 0.0))
    dw = (a * xa - b * xb) / (2.0 * xs * np.maximum(w, 1e-12))
    # Laminar end: (4.1c) has an infinite slope at p_d = p_u; continue it linearly above X_LAMINAR.
    lam = xs > X_LAMINAR
    w = np.where(lam, W_LAMINAR * (1.0 - xs) / (1.0 - X_LAMINAR), w)
    dw = np.where(lam, -W_LAMINAR / (1.0 - X_LAMINAR), dw)
    z = np.where(choked, beta * pu, alpha * pu * w)
    dzu = np.where(choked, beta, alpha * (w - xs * dw))
    dzd = np.where(choked, 0.0, alpha * dw)
    return z, dzu, dzd


def flow_function(pu, pd, gas: GasConstants = GasConstants()):
    """Thin-plate flow function phi(p_u, p_d), thesis eq. (4.1b-c), kg/(s m²).

    Parameters
    ----------
    pu, pd : array_like, upstream and downstream absolute pressure, Pa (broadcast together)
    """
    return flow_function_and_derivatives(pu, pd, gas)[0]


def flow_function_and_derivatives(pu, pd, gas: GasConstants = GasConstants()):
    """phi(p_u, p_d) of thesis eq. (4.1b) with d phi/d p_u and d phi/d p_d."""
    pu, pd = np.broadcast_arrays(np.asarray(pu, float), np.asarray(pd, float))
    fwd = pu >= pd
    z1, d1u, d1d = z_flow(pu, pd, gas)
    z2, d2u, d2d = z_flow(pd, pu, gas)  # reversed flow: phi = -z(p_d, p_u)
    phi = np.where(fwd, z1, -z2)
    dphi_u = np.where(fwd, d1u, -d2d)
    dphi_d = np.where(fwd, d1d, -d2u)
    return phi, dphi_u, dphi_d


def smax(x):
    """Smooth max(x, 0): (sqrt(x² + 1) + x) / 2 (thesis §4.2.1, before eq. 4.3)."""
    return 0.5 * (np.sqrt(x * x + 1.0) + x)


@dataclass(frozen=True)
class ValveGeometry:
    """Constants of the proportional valve, thesis eq. (4.3); arrays of shape (C,) or scalars.

    Attributes
    ----------
    U_c, U_r : voltage at which the compressor / room port is sealed, V
    L_c, L_r : leakage area of the sealed compressor / room port, m²
    B : area per volt, m²/V
    smooth : area scale of the smooth max, m² (see module doc)
    """

    U_c: np.ndarray
    U_r: np.ndarray
    L_c: np.ndarray
    L_r: np.ndarray
    B: np.ndarray
    smooth: float = 0.3e-6

    def areas(self, u):
        """Port areas (a_c, a_r) in m² for valve voltage ``u`` (V), thesis eq. (4.3a-b)."""
        w = self.smooth
        a_c = self.L_c + w * smax(((u - self.U_c) * self.B - self.L_c) / w)
        a_r = self.L_r + w * smax(((self.U_r - u) * self.B - self.L_r) / w)
        return a_c, a_r


def mass_flow(p, a_c, a_r, supply, room, gas: GasConstants = GasConstants()):
    """Net mass flow into a two-port chamber and its derivative in p, thesis eq. (4.2) / (4.4b).

    Parameters
    ----------
    p : array (C,), chamber pressure, Pa
    a_c, a_r : arrays (C,), port areas, m²
    supply, room : compressor pressure P_c and room pressure P_r, Pa (scalars or (C,))

    Returns
    -------
    m_dot, dm_dot/dp : arrays (C,), kg/s and kg/(s Pa)
    """
    phi_c, _, dphi_c_d = flow_function_and_derivatives(supply, p, gas)
    phi_r, dphi_r_u, _ = flow_function_and_derivatives(p, room, gas)
    return a_c * phi_c - a_r * phi_r, a_c * dphi_c_d - a_r * dphi_r_u


def pressure_rate(p, m_dot, dm_dp, volume, volume_rate, gas: GasConstants = GasConstants()):
    """Chamber pressure dynamics, thesis eq. (4.4a), and its derivative in p.

    .. math:: \\dot p = \\kappa \\frac{R T}{M v} \\dot m - \\kappa \\frac{\\dot v}{v} p

    Parameters
    ----------
    p : (C,) Pa; m_dot, dm_dp : (C,) from :func:`mass_flow`; volume (C,) m³; volume_rate (C,) m³/s

    Returns
    -------
    p_dot : (C,) Pa/s;  dp_dot/dp : (C,) 1/s
    """
    k = gas.kappa
    flow_gain = k * gas.rt_over_m / volume
    comp = k * volume_rate / volume
    return flow_gain * m_dot - comp * p, flow_gain * dm_dp - comp


def steady_state_pressure(
    u, valve: ValveGeometry, supply, room, gas: GasConstants = GasConstants(), iterations: int = 80
):
    """p_ss(u): root of m_dot(p) = 0 for a locked chamber (thesis §4.3.1, Fig. 4.7), Pa.

    m_dot is monotonically decreasing in p on [P_r, P_c] (Fig. 4.4), so bisection is exact.
    ``u`` and the valve's arrays broadcast together.
    """
    a_c, a_r = valve.areas(np.asarray(u, float))
    lo = np.full(np.broadcast(a_c, a_r).shape, float(np.min(room)))
    hi = np.full_like(lo, float(np.max(supply)))
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        m, _ = mass_flow(mid, a_c, a_r, supply, room, gas)
        lo = np.where(m > 0, mid, lo)
        hi = np.where(m > 0, hi, mid)
    return 0.5 * (lo + hi)
