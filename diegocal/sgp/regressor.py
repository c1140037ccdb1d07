"""The parametric part f(u) of the SGP for an articulated robot: the joint-torque regressor.

For an open-chain robot the inverse dynamics are linear in the dynamic parameters (thesis
eq. 3.29-3.30): ``tau = f(q, qd, qdd) w``. Here ``f`` is Pinocchio's
``computeJointTorqueRegressor`` (n × 10·L, ten inertial parameters per joint body in Pinocchio's
order ``m, mc_x, mc_y, mc_z, I_xx, I_xy, I_yy, I_xz, I_yz, I_zz``) followed by friction columns
(thesis eq. 3.29: viscous ``qd_j η_v,j`` and Coulomb ``sign(qd_j) η_c,j``), one per joint and kind:
the ``viscous_friction`` and ``coulomb_friction`` terms of :mod:`diegocal.sgp.terms`, whose other
terms a model may carry as extra columns (``DynamicsModel(terms=...)``).

Many inertial parameters are not identifiable from torques; :func:`base_parameters` reduces the
columns to a set of base parameters by QR with column pivoting of a regressor stacked over
random states (structural identifiability, independent of the training trajectory).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from scipy.linalg import qr

from diegocal.errors import FitError
from diegocal.sgp.terms import friction_column, friction_terms, parameter_labels

FRICTION_KINDS = ("viscous", "coulomb")
INERTIAL_NAMES = ("m", "mc_x", "mc_y", "mc_z", "I_xx", "I_xy", "I_yy", "I_xz", "I_yz", "I_zz")


def check_friction(friction) -> tuple[str, ...]:
    """Coerce a friction selection to a tuple in canonical order; unknown kinds raise ValueError."""
    friction = tuple(friction)
    bad = [f for f in friction if f not in FRICTION_KINDS]
    if bad:
        raise ValueError(f"unknown friction kind(s) {bad}; expected a subset of {list(FRICTION_KINDS)}")
    return tuple(f for f in FRICTION_KINDS if f in friction)


def parameter_names(robot, friction=FRICTION_KINDS) -> tuple[str, ...]:
    """Names of the full regressor's columns: ``<joint>.<inertial>`` (the rigid body's), then the
    friction terms' labels, ``viscous_friction:<joint>.viscous`` and ``coulomb_friction:<joint>.coulomb``
    (:func:`diegocal.sgp.terms.parameter_labels`)."""
    names = [f"{j}.{p}" for j in robot.joint_names for p in INERTIAL_NAMES]
    for kind in check_friction(friction):
        names += [label for t in friction_terms(robot.joint_names, (kind,)) for label in parameter_labels(t)]
    return tuple(names)


def full_regressor(robot, q, qd, qdd, friction=FRICTION_KINDS) -> np.ndarray:
    """Joint-torque regressor with friction columns (thesis eq. 3.30, f(u) of eq. 3.2).

    Parameters
    ----------
    robot : diegocal.robot.Robot
    q, qd, qdd : ndarray of shape (T, n); rad, rad/s, rad/s² (m, m/s, m/s² for prismatic joints)
    friction : subset of ("viscous", "coulomb")

    Returns
    -------
    ndarray of shape (T, n, 10·n + n·len(friction)); ``F[t] @ w`` is the torque in N·m (N).
    """
    q, qd, qdd = (robot.check_q(x) for x in (q, qd, qdd))
    friction = check_friction(friction)
    T, n = q.shape
    model, data = robot.model, robot.data
    out = np.zeros((T, n, 10 * n + n * len(friction)))
    for t in range(T):
        out[t, :, : 10 * n] = pin.computeJointTorqueRegressor(model, data, q[t], qd[t], qdd[t])
    col = 10 * n
    eye = np.arange(n)
    for kind in friction:  # the friction terms of diegocal.sgp.terms, one per joint
        out[:, eye, col + eye] = friction_column(kind, qd)
        col += n
    return out


#: Samples per chunk of :func:`base_regressor`: the full regressor of one chunk is held at a time
#: (a 9-joint arm: about 8 MB), never that of a whole long log (600,000 samples at 1 kHz: 4.7 GB).
CHUNK = 1000


def base_regressor(robot, q, qd, qdd, base: BaseParameters, friction=FRICTION_KINDS, rows=None) -> np.ndarray:
    """The base regressor ``base.project(full_regressor(...)[:, rows])``, built :data:`CHUNK`
    samples at a time so that the full regressor of a long log is never held.

    q, qd, qdd : (T, n) rad, rad/s, rad/s²; ``rows``: the joints whose torque rows are kept (all
    by default). Returns (T, k, r); ``F[t] @ w_base`` is the torque of those joints in N·m.
    """
    q, qd, qdd = (robot.check_q(x) for x in (q, qd, qdd))
    joints = np.arange(robot.n_joints) if rows is None else np.asarray(rows, int)
    out = np.empty((q.shape[0], joints.size, base.n_base))
    every = np.array_equal(joints, np.arange(robot.n_joints))
    for i in range(0, q.shape[0], CHUNK):
        sl = slice(i, i + CHUNK)
        full = full_regressor(robot, q[sl], qd[sl], qdd[sl], friction)
        # base.project of those rows: one gather along the parameters, written in place ("clip":
        # the indices are valid, so numpy needs no buffer; 2.5x faster than a broadcast fancy index)
        np.take(full if every else full[:, joints], base.independent, axis=2, out=out[sl], mode="clip")
    return out


def true_parameters(robot, friction_values: dict | None = None, friction=FRICTION_KINDS) -> np.ndarray:
    """The full parameter vector of the robot's URDF inertias (+ given friction coefficients).

    ``friction_values`` maps ``"viscous"``/``"coulomb"`` to arrays of shape (n,) (N·m·s/rad, N·m);
    missing kinds are zero. Used by tests to compare identified base parameters with the truth.
    """
    w = [robot.model.inertias[i].toDynamicParameters() for i in range(1, robot.model.njoints)]
    extra = [
        np.asarray((friction_values or {}).get(k, np.zeros(robot.n_joints)), float) for k in check_friction(friction)
    ]
    return np.concatenate(w + extra)


@dataclass(frozen=True)
class BaseParameters:
    """Identifiable linear combinations of the full parameters (QR with column pivoting).

    ``w_base = w_full[independent] + beta @ w_full[dependent]`` and
    ``F_base = F_full[..., independent]`` gives ``F_full @ w_full == F_base @ w_base``.

    Attributes
    ----------
    independent : ndarray of int, shape (r,)
    dependent : ndarray of int, shape (d,)
    beta : ndarray of shape (r, d)
    names : tuple of str, length r, names of the base parameters (the independent column's name)
    """

    independent: np.ndarray
    dependent: np.ndarray
    beta: np.ndarray
    names: tuple[str, ...]

    @property
    def n_base(self) -> int:
        return int(self.independent.size)

    def project(self, F: np.ndarray) -> np.ndarray:
        """Base regressor: F (..., n_full) -> (..., r)."""
        return F[..., self.independent]

    def from_full(self, w_full: np.ndarray) -> np.ndarray:
        """Base parameters (r,) from a full parameter vector (n_full,)."""
        return w_full[self.independent] + self.beta @ w_full[self.dependent]

    def to_dict(self) -> dict:
        return {
            "independent": self.independent,
            "dependent": self.dependent,
            "beta": self.beta,
            "names": np.array(self.names),
        }

    @classmethod
    def from_dict(cls, d: dict) -> BaseParameters:
        return cls(
            np.asarray(d["independent"], int),
            np.asarray(d["dependent"], int),
            np.asarray(d["beta"], float),
            tuple(str(x) for x in d["names"]),
        )


def base_parameters(
    robot,
    friction=FRICTION_KINDS,
    n_samples: int = 200,
    seed: int = 0,
    tol: float = 1e-8,
    rows=None,
) -> BaseParameters:
    """Base parameters from QR with column pivoting of a regressor stacked over random states.

    States: q uniform within the joint limits (clipped to [-π, π]), qd and qdd standard normal
    (rad/s, rad/s²). Columns whose diagonal ``|R_kk|`` falls below ``tol · |R_00|`` are dependent.
    ``rows`` (joint indices) keeps only those joints' torque rows: the parameters identifiable
    from the torques of a subset of the joints (e.g. a robot whose wrist torques are not measured).
    """
    rng = np.random.default_rng(seed)
    n = robot.n_joints
    lo = np.maximum(robot.lower, -np.pi)
    hi = np.minimum(robot.upper, np.pi)
    q = rng.uniform(lo, hi, size=(n_samples, n))
    qd = rng.standard_normal((n_samples, n))
    qdd = rng.standard_normal((n_samples, n))
    F = full_regressor(robot, q, qd, qdd, friction)
    if rows is not None:
        F = F[:, list(rows), :]
    F = F.reshape(-1, F.shape[2])
    _, R, piv = qr(F, mode="economic", pivoting=True)
    diag = np.abs(np.diag(R))
    if diag.size == 0 or diag[0] == 0:
        raise FitError("the torque regressor is identically zero: no parameter is identifiable")
    r = int(np.sum(diag > tol * diag[0]))
    beta = np.linalg.solve(R[:r, :r], R[:r, r:])
    beta[np.abs(beta) < 1e-10] = 0.0
    names = parameter_names(robot, friction)
    return BaseParameters(piv[:r].copy(), piv[r:].copy(), beta, tuple(names[i] for i in piv[:r]))


def nominal_torque(robot, q, qd, qdd) -> np.ndarray:
    """(T, n): the rigid body's torque with the URDF's inertias (eq. 3.30 with w = the URDF's
    inertial parameters, no friction; Pinocchio's regressor times them, i.e. its RNEA)."""
    n = robot.n_joints
    w = true_parameters(robot, friction=())[: 10 * n]
    q, qd, qdd = (robot.check_q(x) for x in (q, qd, qdd))
    out = np.empty((len(q), n))
    for i in range(0, len(q), CHUNK):  # a chunk's regressor at a time (regressor.CHUNK)
        sl = slice(i, i + CHUNK)
        out[sl] = full_regressor(robot, q[sl], qd[sl], qdd[sl], ())[:, :, : 10 * n] @ w
    return out
