"""Forward kinematics and point Jacobians vectorised over frames (the STAC inner loop, the simulator).

:meth:`diegocal.robot.Robot.points_jacobian` calls Pinocchio once per frame from Python, which
dominates a STAC run at thesis size (25,000 frames x 38 joints). :class:`BatchKinematics` reads
the joint placements and axes from the Pinocchio model once and then evaluates, for all frames
at once, the chain of 3x3 products ``world_T_joint[j] = world_T_joint[parent] @ placement[j] @
motion(q_j)``. The point Jacobian columns are the standard geometric ones (thesis eq. 2.23):

.. math:: \\partial x / \\partial q_j = a_j \\times (x - o_j) \\ (revolute), \\quad a_j \\ (prism.)

for every joint j that is an ancestor of the point's link, with ``a_j`` the joint axis and
``o_j`` its origin, everything expressed in the base frame. When joints also move the base
link (the base is not the URDF root) a joint that moves both the point and the base leaves
their relative position unchanged, and one that moves only the base contributes with the
opposite sign: the column is ``(anc_point - anc_base) * a_j x (x - o_j)``.

The tests check that this equals ``Robot.points`` and ``Robot.points_jacobian`` (two routes agree).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from diegocal.errors import RobotConfigError
from diegocal.robot.model import PointSet, Robot

_AXES = {"X": (1.0, 0.0, 0.0), "Y": (0.0, 1.0, 0.0), "Z": (0.0, 0.0, 1.0)}


@dataclass(frozen=True)
class Poses:
    """Joint frames of a batch, in the base frame.

    R : (B, n, 3, 3) joint rotations; p : (B, n, 3) joint origins, m;
    axis : (B, n, 3) joint axes (unit vectors);
    root_R : (B, 3, 3), root_p : (B, 3) the URDF root (world) frame in the base frame.
    """

    R: np.ndarray
    p: np.ndarray
    axis: np.ndarray
    root_R: np.ndarray
    root_p: np.ndarray


class BatchKinematics:
    """Vectorised forward kinematics of a :class:`Robot` (only one-DoF joints, as Robot enforces).

    Parameters
    ----------
    robot : Robot
    """

    def __init__(self, robot: Robot):
        model = robot.model
        self.robot = robot
        self.n = robot.n_joints
        self.parent = np.array([model.parents[j] - 1 for j in range(1, model.njoints)], dtype=int)
        self.place_R = np.array([model.jointPlacements[j].rotation for j in range(1, model.njoints)]).reshape(-1, 3, 3)
        self.place_p = np.array([model.jointPlacements[j].translation for j in range(1, model.njoints)]).reshape(-1, 3)
        self.local_axis = np.zeros((self.n, 3))
        self.prismatic = np.zeros(self.n, dtype=bool)
        for j in range(1, model.njoints):
            jm = model.joints[j]
            kind = jm.shortname().replace("JointModel", "")
            if kind in ("RX", "RY", "RZ", "PX", "PY", "PZ"):
                self.local_axis[j - 1] = _AXES[kind[1]]
                self.prismatic[j - 1] = kind[0] == "P"
            elif kind in ("RevoluteUnaligned", "PrismaticUnaligned"):
                self.local_axis[j - 1] = np.asarray(jm.extract().axis, float)
                self.prismatic[j - 1] = kind.startswith("Prismatic")
            else:
                raise RobotConfigError(f"joint {model.names[j]!r}: joint type {kind} is not supported by STAC")
        if np.any(self.parent >= np.arange(self.n)):
            raise RobotConfigError("joint order is not topological (a parent after its child)")
        # ancestors[j, k]: joint k moves the child link of joint j (k is j or an ancestor of j)
        anc = np.zeros((self.n + 1, self.n), dtype=bool)  # row 0 = the universe (root) joint
        for j in range(self.n):
            anc[j + 1] = anc[self.parent[j] + 1]
            anc[j + 1, j] = True
        self._anc = anc
        base = model.frames[robot.base_frame]
        self.base_joint = base.parentJoint  # 0 = the root: the base does not move
        self.base_R = np.asarray(base.placement.rotation)
        self.base_p = np.asarray(base.placement.translation)

    # ------------------------------------------------------------------ links
    def link_info(self, links) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Parent joint index (L,) (Pinocchio numbering, 0 = root), placement R (L,3,3), p (L,3)."""
        model = self.robot.model
        fids = [self.robot.frame_id(link) for link in links]
        joint = np.array([model.frames[f].parentJoint for f in fids], dtype=int)
        R = np.array([model.frames[f].placement.rotation for f in fids]).reshape(-1, 3, 3)
        p = np.array([model.frames[f].placement.translation for f in fids]).reshape(-1, 3)
        return joint, R, p

    def moves(self, link: str) -> bool:
        """Whether any joint moves ``link`` relative to the base link."""
        joint, _, _ = self.link_info([link])
        return bool(np.any(self._anc[joint[0]] != self._anc[self.base_joint]))

    # ------------------------------------------------------------------ forward kinematics
    def joint_poses(self, q: np.ndarray) -> Poses:
        """World->joint chain for a batch, re-expressed in the base frame. q: (B, n) rad or m."""
        q = np.asarray(q, float)
        B = q.shape[0]
        R = np.empty((B, self.n, 3, 3))
        p = np.empty((B, self.n, 3))
        for j in range(self.n):
            a = self.local_axis[j]
            if self.parent[j] < 0:
                Rp, pp = self.place_R[j][None], self.place_p[j][None]
            else:
                Rp = R[:, self.parent[j]] @ self.place_R[j]
                pp = R[:, self.parent[j]] @ self.place_p[j] + p[:, self.parent[j]]
            if self.prismatic[j]:
                R[:, j] = Rp
                p[:, j] = pp + (Rp @ a) * q[:, j, None]
            else:
                R[:, j] = Rp @ _rotation(a, q[:, j])
                p[:, j] = pp
        # base frame: base_T_world = (world_T_joint[b] @ placement)^-1
        if self.base_joint == 0:
            Rb = np.broadcast_to(self.base_R, (B, 3, 3))
            pb = np.broadcast_to(self.base_p, (B, 3))
        else:
            Rb = R[:, self.base_joint - 1] @ self.base_R
            pb = R[:, self.base_joint - 1] @ self.base_p + p[:, self.base_joint - 1]
        RbT = np.swapaxes(Rb, -1, -2)
        Rout = RbT[:, None] @ R
        pout = np.einsum("bij,bnj->bni", RbT, p - pb[:, None])
        axis = (Rout @ self.local_axis[None, :, :, None])[..., 0]
        return Poses(Rout, pout, axis, np.ascontiguousarray(RbT), -(RbT @ pb[..., None])[..., 0])

    def link_poses(self, poses: Poses, links) -> tuple[np.ndarray, np.ndarray]:
        """Rotation (B, L, 3, 3) and origin (B, L, 3) of each link in the base frame."""
        joint, Rl, pl = self.link_info(links)
        B = poses.R.shape[0]
        Rj, pj = self._joint_or_root(poses, joint, B)
        return Rj @ Rl, (Rj @ pl[None, :, :, None])[..., 0] + pj

    def points(self, poses: Poses, points: PointSet) -> np.ndarray:
        """Point positions in the base frame: (B, N, 3), m."""
        R, p = self.link_poses(poses, points.links)
        return (R @ np.asarray(points.xyz, float)[None, :, :, None])[..., 0] + p

    def points_jacobian(self, poses: Poses, points: PointSet) -> tuple[np.ndarray, np.ndarray]:
        """Points (B, N, 3) and their Jacobians (B, N, 3, n) in the base frame (eq. 2.23)."""
        x = self.points(poses, points)
        joint, _, _ = self.link_info(points.links)
        sign = self._anc[joint].astype(float) - self._anc[self.base_joint].astype(float)  # (N, n)
        rel = x[:, :, None, :] - poses.p[:, None, :, :]  # (B, N, n, 3)
        cols = np.cross(np.broadcast_to(poses.axis[:, None], rel.shape), rel)
        if self.prismatic.any():
            cols[:, :, self.prismatic] = poses.axis[:, None, self.prismatic]
        J = np.swapaxes(cols * sign[None, :, :, None], -1, -2)
        return x, J

    def _joint_or_root(self, poses: Poses, joint: np.ndarray, B: int):
        """Pose of Pinocchio joint indices (0 = root, expressed in the base frame) for a batch."""
        Rj = np.empty((B, len(joint), 3, 3))
        pj = np.empty((B, len(joint), 3))
        moving = joint > 0
        Rj[:, moving] = poses.R[:, joint[moving] - 1]
        pj[:, moving] = poses.p[:, joint[moving] - 1]
        if (~moving).any():
            Rj[:, ~moving] = poses.root_R[:, None]
            pj[:, ~moving] = poses.root_p[:, None]
        return Rj, pj


def _rotation(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rodrigues' formula for a fixed unit axis (3,) and angles (B,): (B, 3, 3)."""
    x, y, z = axis
    K = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    s, c = np.sin(angle)[:, None, None], np.cos(angle)[:, None, None]
    return np.eye(3) + s * K + (1.0 - c) * (K @ K)
