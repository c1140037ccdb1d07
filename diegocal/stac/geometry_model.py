"""The observation model of :mod:`diegocal.stac.geometry`: θ's layout, the markers and their
Jacobians at static poses, the poses' means and the noise model's eigenbasis.

Markers at the joint angles the pots give (thesis eq. 2.2, 2.11-2.12), with each joint's
placement composed with ``SE3(exp(r), d)`` (``joint_geometry``); the Jacobian with respect to a
joint's (d, r) is that of a small rigid motion of the frame it perturbs, as eq. (2.23) writes a
joint's column: ∂p/∂d = R_F, ∂p/∂r = −[p − o_F]× R_F.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from scipy.optimize import minimize

from diegocal.errors import FitError
from diegocal.io import Log
from diegocal.robot import Robot
from diegocal.robot.model import perturb_joint_placements
from diegocal.stac.calibration import Calibration
from diegocal.stac.static import static_poses

#: The six parameters of a joint's deviation, in the order of ``joint_geometry``.
GEOMETRY = ("dx", "dy", "dz", "rx", "ry", "rz")


@dataclass(frozen=True)
class Layout:
    """Where each parameter sits in θ: ``names`` (p,) like ``frame.rx``, ``m01.x``, ``j2.bias``,
    ``j2.gain``, ``joint_geometry:j2.dx``; ``group`` (p,) 0 frame and markers, 1 pots, 2 geometry
    (the order in which :func:`identifiable` keeps them); ``pots`` (P',) indices of the pots fitted
    and ``joints`` (P',) their joints' indices; ``gains`` (P',) bool, the pot's gain is fitted
    (not an encoder's); ``geometry`` the joint names with a deviation."""

    names: tuple[str, ...]
    group: np.ndarray
    pots: np.ndarray
    joints: np.ndarray
    gains: np.ndarray
    geometry: tuple[str, ...]
    n_markers: int


# ----------------------------------------------------------------------------- the model
def layout(robot: Robot, cal: Calibration) -> Layout:
    """θ's layout for ``robot`` (every joint that moves a marker gets a deviation and, through its
    rotary pot or encoder, a bias; a rotary pot also a gain)."""
    model = robot.model
    if model.frames[robot.base_frame].parentJoint != 0:
        raise FitError(
            f"--geometry needs a base link no joint moves; {robot.sensors.base_link!r} hangs from joint "
            f"{model.names[model.frames[robot.base_frame].parentJoint]!r}"
        )
    moving = set()
    for m in robot.sensors.markers:
        moving |= {i - 1 for i in model.supports[model.frames[robot.frame_id(m.link)].parentJoint] if i > 0}
    pots, joints, gains = [], [], []
    for i, p in enumerate(robot.sensors.pots):
        if p.kind in ("rotary", "encoder") and robot.joint_index(p.joint) in moving:
            if robot.joint_index(p.joint) in joints:
                continue
            pots.append(i)
            joints.append(robot.joint_index(p.joint))
            gains.append(p.kind == "rotary")
    missing = sorted(moving - set(joints))
    if missing:
        names = ", ".join(robot.joint_names[j] for j in missing)
        raise FitError(f"--geometry needs a rotary pot or encoder on every joint that moves a marker; none on {names}")
    names = [f"frame.{a}" for a in ("x", "y", "z", "rx", "ry", "rz")]
    names += [f"{m}.{a}" for m in cal.marker_names for a in "xyz"]
    group = [0] * len(names)
    names += [f"{cal.pot_names[i]}.bias" for i in pots] + [
        f"{cal.pot_names[i]}.gain" for i, g in zip(pots, gains, strict=True) if g
    ]
    group += [1] * (len(names) - len(group))
    geometry = tuple(robot.joint_names[j] for j in sorted(moving))
    names += [f"joint_geometry:{j}.{a}" for j in geometry for a in GEOMETRY]
    group += [2] * (len(names) - len(group))
    return Layout(
        tuple(names),
        np.array(group),
        np.array(pots, int),
        np.array(joints, int),
        np.array(gains, bool),
        geometry,
        len(cal.marker_names),
    )


@dataclass(frozen=True)
class State:
    """θ in its natural form: mocap R (3, 3), T (3,), markers (M, 3), gain and bias (P,) of every
    pot (sensors.yaml order), geometry (G, 6)."""

    R: np.ndarray
    T: np.ndarray
    markers: np.ndarray
    gain: np.ndarray
    bias: np.ndarray
    geometry: np.ndarray

    def step(self, lay: Layout, delta: np.ndarray) -> State:
        """θ moved by ``delta`` (p,): the frame's rotation on the left, a joint's deviation composed
        on the right (SE3(exp(r), d) · SE3(exp(δr), δd), the motion :func:`observe` differentiates),
        the rest added."""
        M = lay.n_markers
        bias, gain = self.bias.copy(), self.gain.copy()
        nb = len(lay.pots)
        bias[lay.pots] += delta[6 + 3 * M : 6 + 3 * M + nb]
        ng = int(lay.gains.sum())
        gain[lay.pots[lay.gains]] += delta[6 + 3 * M + nb : 6 + 3 * M + nb + ng]
        geo = self.geometry.copy()
        for g, (v, dv) in enumerate(zip(self.geometry, delta[6 + 3 * M + nb + ng :].reshape(-1, 6), strict=True)):
            R = pin.exp3(v[3:])
            geo[g] = np.r_[v[:3] + R @ dv[:3], pin.log3(R @ pin.exp3(dv[3:]))]
        return State(
            pin.exp3(delta[3:6]) @ self.R,
            self.T + delta[:3],
            self.markers + delta[6 : 6 + 3 * M].reshape(M, 3),
            gain,
            bias,
            geo,
        )


def observe(robot: Robot, lay: Layout, state: State, links, pots: np.ndarray):
    """Markers (K, M, 3) in the mocap frame at pose readings ``pots`` (K, P) for markers on
    ``links`` (M,) link names, their Jacobian (K, M, 3, p) with respect to θ (the frame's rotation
    on the left; a joint's deviation d, r at the placement it perturbs, eq. 2.23's way), and
    ∂x/∂q (K, M, 3, n), m/rad (for the pot noise)."""
    model = perturb_joint_placements(robot.model, dict(zip(lay.geometry, state.geometry, strict=True)))
    data = model.createData()
    K, M, n = pots.shape[0], lay.n_markers, robot.n_joints
    q = robot.neutral()[None].repeat(K, axis=0)
    q[:, lay.joints] = (pots[:, lay.pots] - state.bias[lay.pots]) / state.gain[lay.pots]  # eq. 2.2
    fids = [robot.frame_id(link) for link in links]
    gjid = [model.getJointId(j) for j in lay.geometry]
    nb, ng = len(lay.pots), int(lay.gains.sum())
    ob, og, oo = 6 + 3 * M, 6 + 3 * M + nb, 6 + 3 * M + nb + ng
    x = np.empty((K, M, 3))
    J = np.zeros((K, M, 3, len(lay.names)))
    Jq = np.zeros((K, M, 3, n))
    R = state.R
    for k in range(K):
        Jw = pin.computeJointJacobians(model, data, q[k])  # (6, n) world, at the origin; runs FK
        pin.updateFramePlacements(model, data)
        base = data.oMf[robot.base_frame]
        RB = R @ base.rotation.T  # world -> mocap
        for m, fid in enumerate(fids):
            f = data.oMf[fid]
            pw = f.act(state.markers[m])
            b = base.rotation.T @ (pw - base.translation)
            x[k, m] = R @ b + state.T
            J[k, m, :, 0:3] = np.eye(3)
            J[k, m, :, 3:6] = -pin.skew(R @ b)
            J[k, m, :, 6 + 3 * m : 9 + 3 * m] = RB @ f.rotation
            support = model.supports[model.frames[fid].parentJoint].tolist()
            cols = np.asarray(support[1:]) - 1
            Jq[k, m, :, cols] = (RB @ (Jw[:3, cols] - pin.skew(pw) @ Jw[3:, cols])).T  # ω × p = −[p]× ω
            for g, jid in enumerate(gjid):
                if jid in support:
                    F = data.oMi[model.parents[jid]] * model.jointPlacements[jid]  # the perturbed frame
                    J[k, m, :, oo + 6 * g : oo + 6 * g + 3] = RB @ F.rotation
                    J[k, m, :, oo + 6 * g + 3 : oo + 6 * g + 6] = -RB @ pin.skew(pw - F.translation) @ F.rotation
    gain = state.gain[lay.pots]
    J[..., ob:og] = Jq[..., lay.joints] * (-1.0 / gain)  # ∂q/∂bias
    qg = q[:, lay.joints[lay.gains]] / gain[lay.gains]
    J[..., og:oo] = Jq[..., lay.joints[lay.gains]] * (-qg)[:, None, None, :]  # ∂q/∂gain
    return x, J, Jq


# ----------------------------------------------------------------------------- the data
@dataclass(frozen=True)
class Poses:
    """Static poses averaged: pots (K, P) in the calibration's pot order, markers (K, M, 3) in
    its marker order (NaN where unseen), count (K,) samples per pose; ids (K,) the pose indices,
    first (K,) each pose's first frame in the log."""

    pots: np.ndarray
    markers: np.ndarray
    count: np.ndarray
    ids: np.ndarray
    first: np.ndarray

    def without(self, written: np.ndarray) -> Poses:
        """The same poses with the markers of ``written`` (K,) bool left out."""
        x = self.markers.copy()
        x[written] = np.nan
        return Poses(self.pots, x, self.count, self.ids, self.first)


def log_poses(log: Log) -> np.ndarray:
    """The pose (T,) int of each sample of a static-pose log (:func:`static_poses`); FitError for a
    log that is not one."""
    poses = static_poses(log)
    if poses is None:
        raise FitError(
            "--geometry needs static poses: this log's pots move within its holds like a moving session's "
            "(each held pose must read as noise around one value)"
        )
    return poses


def pose_means(log: Log, cal: Calibration, poses: np.ndarray | None = None) -> Poses:
    """Average each static pose of ``log`` (:func:`static_poses`); the markers of STAC's written-off
    frames (``cal.rejected``, a robust loss's) are left out."""
    poses = log_poses(log) if poses is None else np.asarray(poses, int)
    pst, mst = log.stream("pots", needed_by="stac --geometry"), log.stream("markers", needed_by="stac --geometry")
    T = log.n_samples
    p = np.full((T, len(cal.pot_names)), np.nan)
    for i, name in enumerate(cal.pot_names):
        if name in pst.names:
            p[:, i] = pst.data[:, pst.names.index(name)]
    x = np.full((T, len(cal.marker_names), 3), np.nan)
    for i, name in enumerate(cal.marker_names):
        if name in mst.names:
            x[:, i] = mst.data[:, mst.names.index(name)]
    bad = np.zeros(T, bool)
    bad[np.asarray(cal.rejected, int)] = True
    x[bad] = np.nan
    ids = np.unique(poses)
    pm = np.array(
        [np.nanmean(p[poses == k], axis=0) if np.isfinite(p[poses == k]).any() else p[poses == k][0] for k in ids]
    )
    with np.errstate(invalid="ignore"):
        xm = np.array(
            [
                np.nanmean(x[poses == k], axis=0) if np.isfinite(x[poses == k]).any() else np.full(x.shape[1:], np.nan)
                for k in ids
            ]
        )
    count = np.array([(poses == k).sum() for k in ids], float)
    first = np.array([np.flatnonzero(poses == k)[0] for k in ids])
    return Poses(pm, xm, count, ids, first)


@dataclass(frozen=True)
class Spectra:
    """The residuals r (N,) and Jacobian (N, p) of the seen marker coordinates rotated, pose by
    pose, into the eigenbasis of B_k = J_q,k diag(1/gain²) J_q,kᵀ (eigenvalues lam (N,)), with
    each row's pose's sample count n (N,): C_k is then diagonal, (σ_m² + s² lam) / n."""

    r: np.ndarray
    J: np.ndarray
    lam: np.ndarray
    n: np.ndarray
    pose: np.ndarray

    def whiten(self, var_m: float, var_p: float):
        """Whitened residuals (N,), Jacobian (N, p) and Σ log det C_k."""
        v = (var_m + var_p * self.lam) / self.n
        w = 1.0 / np.sqrt(v)
        return self.r * w, self.J * w[:, None], float(np.log(v).sum())


def spectra(r, J, Jq, lay: Layout, state: State, poses: Poses) -> Spectra:
    """:class:`Spectra` of residuals r (K, M, 3) and Jacobians J (K, M, 3, p), Jq (K, M, 3, n)."""
    rows, cols, lams, ns, ks = [], [], [], [], []
    g2 = 1.0 / state.gain[lay.pots] ** 2
    for k in range(r.shape[0]):
        seen = np.isfinite(r[k]).all(axis=-1)
        if not seen.any():
            continue
        A = Jq[k, seen][..., lay.joints].reshape(-1, len(lay.joints))
        lam, U = np.linalg.eigh((A * g2) @ A.T)
        rows.append(U.T @ r[k, seen].reshape(-1))
        cols.append(U.T @ J[k, seen].reshape(-1, J.shape[-1]))
        lams.append(np.maximum(lam, 0.0))
        ns.append(np.full(lam.size, poses.count[k]))
        ks.append(np.full(lam.size, k))
    return Spectra(np.concatenate(rows), np.vstack(cols), np.concatenate(lams), np.concatenate(ns), np.concatenate(ks))


def variances(spec: Spectra, var_m: float, var_p: float, dof: int) -> tuple[float, float]:
    """(σ_m², s²) maximising the Gaussian likelihood of the residuals, then scaled so that the
    whitened χ² equals ``dof`` (the residuals of a fit are smaller than the noise)."""
    r2 = spec.r**2

    def nll(z):
        v = (np.exp(z[0]) + np.exp(z[1]) * spec.lam) / spec.n
        return float(np.sum(np.log(v) + r2 / v))

    z0 = np.log([max(var_m, 1e-14), max(var_p, 1e-16)])
    z = minimize(nll, z0, method="Nelder-Mead", options={"xatol": 1e-4, "fatol": 1e-8}).x
    vm, vp = float(np.exp(z[0])), float(np.exp(z[1]))
    rw, _, _ = spec.whiten(vm, vp)
    c = float(rw @ rw) / max(dof, 1)
    return vm * c, vp * c
