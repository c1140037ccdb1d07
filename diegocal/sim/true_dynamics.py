"""The simulated robot's true dynamics (:mod:`diegocal.sim.dynamics` builds it): its Pinocchio model
(a payload's, an armature's), joint friction, the injected joint effects as physical shapes of
their own, and the torque sensor. Torques in N·m, samples first."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from diegocal.sim.kinematic_effects import backlash

#: velocity (rad/s) over which the coupled motor's Coulomb friction changes sign (tanh)
COUPLED_SMOOTHING = 0.05
#: the effects whose torque switches with sign(qd): the smooth dynamics (:meth:`TrueDynamics.linearise`)
#: leave them out, as they leave out the joints' Coulomb friction
SIGN_LIKE = ("coulomb_friction", "position_friction", "stribeck_friction", "load_friction")


@dataclass(frozen=True)
class EffectTerm:
    """One injected joint effect: its truth record and which joint column ``j`` it adds to."""

    cause: str
    j: int
    record: dict

    def torque(self, q: np.ndarray, qd: np.ndarray, load: np.ndarray | None = None) -> np.ndarray:
        """Added torque (T,) N·m on joint ``j`` for q, qd of shape (T, n); ``load`` (T, n) N·m, the
        torque the rigid body applies (a ``load_friction`` needs it)."""
        v, qj, vj = self.record["values"], q[:, self.j], qd[:, self.j]
        if self.cause == "coulomb_friction":
            return v["coulomb"] * np.sign(vj)
        if self.cause == "viscous_friction":
            return v["viscous"] * vj
        if self.cause == "spring":
            return v["stiffness"] * (qj - v["rest"])
        if self.cause == "position_friction":
            r = self.record["region"]
            inside = (qj >= r["low"]) & (qj <= r["high"])
            return inside * (v["coulomb"] * np.sign(vj) + v["viscous"] * vj)
        if self.cause == "coupled_friction":
            motor = vj + v["ratio"] * qd[:, int(v["partner_index"])]
            return v["coulomb"] * np.tanh(motor / v.get("smoothing", COUPLED_SMOOTHING)) + v["viscous"] * motor
        if self.cause == "stribeck_friction":  # the peak of static friction above Coulomb's level
            return v["amplitude"] * np.sign(vj) * np.exp(-np.abs(vj) / v["velocity_scale"])
        if self.cause == "load_friction":  # a gear's friction grows with the torque it transmits
            if load is None:
                raise ValueError("load_friction needs the rigid body's torque (prescribed trajectories only)")
            return v["coefficient"] * np.abs(load[:, self.j]) * np.sign(vj)
        # torque_offset (a sensor bias), armature (in the model), torque_lag and torque_gain (the
        # sensor), transmission_backlash (the link's angle: TrueDynamics.link_angles)
        return np.zeros_like(qj)


class TrueDynamics:
    """The simulated robot's true dynamics: a (payload-modified) Pinocchio model, joint friction and
    physical effect terms, plus the torque sensor's offset.

    Attributes
    ----------
    model : pinocchio.Model, viscous (n,) N·m·s/rad, coulomb (n,) N·m, terms : list of EffectTerm,
    offset (n,) N·m added to measured torques only, records : list of dict (/truth effects).
    """

    def __init__(self, model, viscous, coulomb, terms, offset, records):
        self.model, self.data = model, model.createData()
        self.viscous, self.coulomb = np.asarray(viscous, float), np.asarray(coulomb, float)
        self.terms, self.offset, self.records = (
            list(terms),
            np.asarray(offset, float),
            list(records),
        )

    def extra_torque(self, q, qd, smooth: bool = False, load: np.ndarray | None = None) -> np.ndarray:
        """Friction and effect torques (T, n) N·m; ``smooth`` drops the sign() terms (:data:`SIGN_LIKE`);
        ``load`` (T, n) N·m: the rigid body's torque, which a ``load_friction`` grows with."""
        q, qd = np.atleast_2d(q), np.atleast_2d(qd)
        out = self.viscous * qd + (0.0 if smooth else self.coulomb * np.sign(qd))
        for t in self.terms:
            if smooth and t.cause in SIGN_LIKE:
                continue
            tau = t.torque(q, qd, load)
            out[:, t.j] += tau
            if t.cause == "coupled_friction":
                v = t.record["values"]
                out[:, int(v["partner_index"])] += v["ratio"] * tau
        return out

    def sensor(self, tau: np.ndarray, time: np.ndarray) -> np.ndarray:
        """What the torque sensors read of the applied torques (T, n): ``torque_lag`` joints
        through a first-order low-pass filter L·y' + y = τ (exact for a torque linear between
        samples, so a lag shorter than a sample still delays), ``torque_gain`` joints times
        (1 + gain_error), + offset."""
        out = np.array(tau, float, copy=True)
        for t in self.terms:
            if t.cause == "torque_gain":
                out[:, t.j] *= 1.0 + t.record["values"]["gain_error"]
            if t.cause != "torque_lag":
                continue
            lag = t.record["values"]["lag"]
            x, y = tau[:, t.j], out[:, t.j]
            for k in range(1, x.size):
                a = np.exp(-(time[k] - time[k - 1]) / lag)
                m = (x[k] - x[k - 1]) / (time[k] - time[k - 1])  # the input's slope in the step
                y[k] = a * (y[k - 1] - x[k - 1] + lag * m) + x[k] - lag * m
        return out + self.offset

    def link_angles(self, q: np.ndarray) -> np.ndarray:
        """The links' angles (T, n) of a motor trajectory q (T, n): a ``transmission_backlash``
        joint's through the simulators' play operator (a dead band of twice the half-width,
        :func:`~diegocal.sim.kinematic_effects.backlash`); the others' are the motor's."""
        link = np.array(q, float, copy=True)
        for t in (t for t in self.terms if t.cause == "transmission_backlash"):
            link[:, t.j] = backlash(q[:, t.j], 2.0 * t.record["values"]["half_width"])
        return link

    def inverse(self, q, qd, qdd) -> np.ndarray:
        """Applied joint torques (T, n) N·m of a trajectory: ``rnea`` at the links' angles
        (:meth:`link_angles`) + friction + effects (no sensor offset). A ``load_friction`` grows
        with the torque the links apply, ``rnea``'s less the rotors' (an armature turns on the
        motor's side of the gear: its torque is no load the gear carries)."""
        q, qd, qdd = (np.atleast_2d(np.asarray(a, float)) for a in (q, qd, qdd))
        link = self.link_angles(q)
        rb = np.array([pin.rnea(self.model, self.data, link[t], qd[t], qdd[t]) for t in range(q.shape[0])])
        return rb + self.extra_torque(q, qd, load=rb - self.model.armature * qdd)

    def forward(self, q, qd, tau, smooth: bool = False) -> np.ndarray:
        """Accelerations (n,) rad/s² for one state and applied torque (n,): ``aba`` on τ − extra."""
        extra = self.extra_torque(q[None], qd[None], smooth)[0]
        return pin.aba(self.model, self.data, q, qd, np.asarray(tau, float) - extra).copy()

    def linearise(self, q_eq: np.ndarray, actuated: np.ndarray, eps: float = 1e-6):
        """A (2n, 2n), B (2n, m) of ẋ = A x + B u about (q_eq, 0), x = [q − q_eq, qd], by central
        differences of the smooth true forward dynamics (sign() friction left out)."""
        n = q_eq.size
        A, B = np.zeros((2 * n, 2 * n)), np.zeros((2 * n, actuated.size))
        A[:n, n:] = np.eye(n)
        zero = np.zeros(n)
        for i in range(2 * n):
            d = np.zeros(2 * n)
            d[i] = eps
            plus = self.forward(q_eq + d[:n], d[n:], zero, smooth=True)
            minus = self.forward(q_eq - d[:n], -d[n:], zero, smooth=True)
            A[n:, i] = (plus - minus) / (2 * eps)
        for k, j in enumerate(actuated):
            u = np.zeros(n)
            u[j] = eps
            B[n:, k] = (self.forward(q_eq, zero, u, True) - self.forward(q_eq, zero, -u, True)) / (2 * eps)
        return A, B
