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

For Gauss-Newton on many points (the STAC q-phase) the dense (B, N, 3, n) Jacobian is mostly
zeros: a point moves only with the joints of its chain. Writing each joint's motion as a twist
ξ_j = (ω_j, v_j) (ω = a_j, v = o_j × a_j for a revolute joint; ω = 0, v = a_j for a prismatic
one), the column is ``v_j + ω_j × x``, and :meth:`BatchKinematics.points_normal` sums
``Σ_m w_m J_mᵀ J_m`` and ``Σ_m J_mᵀ f_m`` over the points without forming J, as the composite
rigid-body algorithm sums link inertias: each point acts as a point mass w_m at x_m, the
masses below joint k are accumulated once (mass, first and second moments), and

.. math:: H_{jk} = s_j s_k\\, ξ_j^T \\hat G_k ξ_k, \\qquad
          \\hat G_k ξ = (c_k × v + (\\mathrm{tr} Q_k - Q_k) ω,\\ μ_k v + ω × c_k)

for k the deeper of the two joints (the points that both move are those that the deeper one
moves); s_j = ±1 is the column sign above. Per frame these are entries of the product
Ξᵀ Y of the twists Ξ (6, n) and Y = (Ĝ_k ξ_k)_k (6, n), formed per block of joints that move
points in common (a leg, the torso with its arms and head): a few small dense products instead
of one gather per pair.

The tests check that these equal ``Robot.points`` and ``Robot.points_jacobian`` (two routes
agree), and that the summed forms equal the dense Jacobian's products.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse.csgraph import connected_components

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


@dataclass(frozen=True)
class _Structure:
    """Which joints move which points: sign (N, n) ∈ {−1, 0, 1}, D = |sign| (N, n), the sign of
    each joint's column (n,); ``pattern`` (n, n) bool is where H can be non-zero (the pairs of
    joints that move points in common); ``blocks``: per connected component of the pattern, its
    joints (a slice when consecutive, else an index array), their index into (n, n) and the
    (k, k) weights that turn the block of Ξᵀ Y into H's upper triangle: s_o s_d at (o, d) for
    each pair with d the deeper joint (it moves a subset of o's points; o == d on the diagonal,
    where the weight is halved), zero elsewhere."""

    sign: np.ndarray
    D: np.ndarray
    sign_joint: np.ndarray
    pattern: np.ndarray
    blocks: tuple


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
        # per joint, the constant right factor of joint_poses: [P, P K, P K², p_place, P a] (3, 11);
        # root joints start from the base frame when the base does not move (base_T_world fixed)
        self._chain = np.zeros((self.n, 3, 11))
        for j in range(self.n):
            K = _skew(self.local_axis[j])
            P, pp = self.place_R[j], self.place_p[j]
            if self.parent[j] < 0 and self.base_joint == 0:
                P, pp = self.base_R.T @ P, self.base_R.T @ (pp - self.base_p)
            self._chain[j] = np.concatenate([P, P @ K, P @ K @ K, pp[:, None], (P @ self.local_axis[j])[:, None]], 1)
        self._chain_t = np.ascontiguousarray(np.swapaxes(self._chain, 1, 2))
        self._links: dict = {}  # links -> (parent joints, placements R, p, all placements identity)
        self._structure: dict = {}
        self._layouts: dict = {}  # (links, blocks) -> points_normal_blocks' layout

    # ------------------------------------------------------------------ links
    def link_info(self, links) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Parent joint index (L,) (Pinocchio numbering, 0 = root), placement R (L,3,3), p (L,3)."""
        key = tuple(links)
        if key not in self._links:  # (one assignment: safe when batches run in threads)
            joint, R, p = self._link_info(key)
            self._links[key] = joint, R, p, bool(np.all(R == np.eye(3)) and np.all(p == 0.0))
        return self._links[key][:3]

    def _link_info(self, links):
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
        """World->joint chain for a batch, re-expressed in the base frame. q: (B, n) rad or m.

        Per joint one (3B, 3) x (3, 11) product: ``R_parent @ [P, P K, P K², p_place, P a]``
        (P the placement rotation, K the axis' cross-product matrix), then Rodrigues' formula
        ``R_j = R_parent P (I + sin q K + (1 − cos q) K²)`` elementwise.
        """
        q = np.asarray(q, float)
        B, n = q.shape[0], self.n
        R = np.empty((n, 3, 3, B))  # component-major while chaining: rows of B are contiguous
        p = np.empty((n, 3, B))
        ax = np.empty((n, 3, B))  # joint axes: R_j a = R_parent P a (Rot(a, q) a = a)
        sin, cos = np.sin(q.T), 1.0 - np.cos(q.T)
        for j in range(n):
            par = self.parent[j]
            if par < 0:
                X = self._chain[j][..., None]
                pp = X[:, 9]
            else:
                X = self._chain_t[j] @ R[par]  # (3, 11, B): R_parent @ [P, PK, PK², p, Pa]
                pp = X[:, 9] + p[par]
            ax[j] = X[:, 10]
            if self.prismatic[j]:
                R[j] = X[:, 0:3]
                p[j] = pp + X[:, 10] * q[:, j]
            else:
                R[j] = X[:, 0:3] + sin[j] * X[:, 3:6] + cos[j] * X[:, 6:9]
                p[j] = pp
        R = R.transpose(3, 0, 1, 2)
        p = p.transpose(2, 0, 1)
        axis = np.ascontiguousarray(ax.transpose(2, 0, 1))
        if self.base_joint == 0:  # the chain started in the base frame (see __init__)
            Rout, pout = np.ascontiguousarray(R), np.ascontiguousarray(p)
            RbT = np.broadcast_to(self.base_R.T, (B, 3, 3))
            root_p = np.broadcast_to(-self.base_R.T @ self.base_p, (B, 3))
        else:  # base_T_world = (world_T_joint[b] @ placement)^-1
            Rb = R[:, self.base_joint - 1] @ self.base_R
            pb = R[:, self.base_joint - 1] @ self.base_p + p[:, self.base_joint - 1]
            RbT = np.swapaxes(Rb, -1, -2)
            Rout = RbT[:, None] @ R
            pout = np.einsum("bij,bnj->bni", RbT, p - pb[:, None])
            root_p = -(RbT @ pb[..., None])[..., 0]
            axis = np.einsum("bij,bnj->bni", RbT, axis)
        return Poses(Rout, pout, axis, np.ascontiguousarray(RbT), np.ascontiguousarray(root_p))

    def twists(self, poses: Poses) -> tuple[np.ndarray, np.ndarray]:
        """Joint twists in the base frame: ω (B, n, 3) and v (B, n, 3), so that a point x on a
        link the joint moves has velocity ``v + ω × x`` per unit joint speed (eq. 2.23)."""
        xi = self.twist_rows(poses)
        return xi[:3].transpose(1, 2, 0), xi[3:].transpose(1, 2, 0)

    def twist_rows(self, poses: Poses) -> np.ndarray:
        """Twists component-major: (6, B, n) = (ω_x, ω_y, ω_z, v_x, v_y, v_z). The point sums
        below take them as ``xi`` when a caller keeps them (STAC re-uses one forward kinematics
        per q for several steps)."""
        a, o = poses.axis, poses.p
        xi = np.empty((6, *a.shape[:2]))
        for i in range(3):
            xi[i] = a[..., i]
        j, k = 1, 2
        for i in range(3):  # v = o × a
            np.multiply(o[..., j], a[..., k], out=xi[3 + i])
            xi[3 + i] -= o[..., k] * a[..., j]
            j, k = k, i
        if self.prismatic.any():
            xi[3:, :, self.prismatic] = xi[:3, :, self.prismatic]
            xi[:3, :, self.prismatic] = 0.0
        return xi

    def link_poses(self, poses: Poses, links) -> tuple[np.ndarray, np.ndarray]:
        """Rotation (B, L, 3, 3) and origin (B, L, 3) of each link in the base frame."""
        joint, Rl, pl = self.link_info(links)
        at_joint = self._links[tuple(links)][3]  # link frames at their joints' frames (as URDF links are)
        B = poses.R.shape[0]
        if np.all(joint > 0):
            Rj, pj = np.take(poses.R, joint - 1, axis=1), np.take(poses.p, joint - 1, axis=1)  # (take: faster)
        else:
            Rj, pj = self._joint_or_root(poses, joint, B)
        if at_joint:
            return Rj, pj
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

    def points_normal(
        self, poses: Poses | None, x: np.ndarray, links, w: np.ndarray, f: np.ndarray, xi: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Gauss-Newton sums over points without their Jacobians J_m (3, n) (eq. 2.23).

        x : (B, N, 3) points in the base frame, m, on ``links`` (N,); w : (B, N) weights;
        f : (B, N, 3) per-point vectors; xi : the twists (6, B, n) of :meth:`twist_rows`, instead
        of ``poses``. Returns ``Σ_m w_m J_mᵀ J_m`` (B, n, n) and ``Σ_m J_mᵀ f_m`` (B, n),
        accumulated as point masses per joint (module docstring).
        """
        st = self._points_structure(links)
        joints = np.arange(self.n)
        blocks = tuple(joints[sel] for sel, _, _ in st.blocks)
        Hb, g = self.points_normal_blocks(poses, x, links, w, f, blocks, xi)
        H = np.zeros((x.shape[0], self.n, self.n))
        for (_, (rows, cols), _), h in zip(st.blocks, Hb, strict=True):
            H[:, rows, cols] = h
        return H, g

    def points_normal_blocks(
        self, poses: Poses | None, x: np.ndarray, links, w: np.ndarray, f: np.ndarray, blocks, xi=None
    ) -> tuple[tuple, np.ndarray]:
        """:meth:`points_normal` with ``Σ_m w_m J_mᵀ J_m`` as its diagonal blocks on ``blocks``
        (index arrays of joints, increasing, each holding whole groups of joints that move points
        in common: H is zero between two blocks): a tuple of (B, k, k), and ``Σ_m J_mᵀ f_m`` (B, n)."""
        st = self._points_structure(links)
        B, N = x.shape[:2]
        xs = [x[..., i] for i in range(3)]
        fs = [f[..., i] for i in range(3)]
        wx = [w * xi for xi in xs]
        mom = np.empty((16, B, N))  # mass μ, first moment c, second moment Q (6), Σ f, Σ x × f
        mom[0] = w
        mom[1:4] = wx
        for r, (i, j) in enumerate(((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))):
            np.multiply(wx[i], xs[j], out=mom[4 + r])
        mom[10:13] = fs
        for i, j, k in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
            np.multiply(xs[j], fs[k], out=mom[13 + i])
            mom[13 + i] -= xs[k] * fs[j]
        acc = (mom.reshape(16 * B, N) @ st.D).reshape(16, B, self.n)  # summed over the points each joint moves
        xi = self.twist_rows(poses) if xi is None else xi
        om, v = xi[:3], xi[3:]
        mu, c = acc[0], acc[1:4]
        xx, yy, zz, xy, xz, yz = acc[4:10]
        Y = np.empty((B, 6, self.n))  # Ĝ_k ξ_k = (c × v + (tr Q − Q) ω, μ v + ω × c)
        Y[:, 0] = (yy + zz) * om[0] - xy * om[1] - xz * om[2] + c[1] * v[2] - c[2] * v[1]
        Y[:, 1] = (xx + zz) * om[1] - xy * om[0] - yz * om[2] + c[2] * v[0] - c[0] * v[2]
        Y[:, 2] = (xx + yy) * om[2] - xz * om[0] - yz * om[1] + c[0] * v[1] - c[1] * v[0]
        Y[:, 3] = mu * v[0] + om[1] * c[2] - om[2] * c[1]
        Y[:, 4] = mu * v[1] + om[2] * c[0] - om[0] * c[2]
        Y[:, 5] = mu * v[2] + om[0] * c[1] - om[1] * c[0]
        XiT = np.ascontiguousarray(xi.transpose(1, 2, 0))  # (B, n, 6)
        out = []
        for k, groups in self._block_layout(links, blocks):
            Hb = None if len(groups) == 1 and groups[0][1] is None else np.zeros((B, k, k))
            for sel, local, C in groups:  # s_o s_d ξ_o · Ĝ_d ξ_d: Ξᵀ Y's upper triangle, mirrored
                U = XiT[:, sel] @ Y[:, :, sel]
                U *= C
                if Hb is None:  # the group is the whole block
                    Hb = U + U.transpose(0, 2, 1)
                else:
                    Hb[:, local[0], local[1]] = U + U.transpose(0, 2, 1)
            out.append(Hb)
        g = (om * acc[13:16]).sum(0) + (v * acc[10:13]).sum(0)  # ξ_k · Σ (x × f, f)
        return tuple(out), g * st.sign_joint

    def _block_layout(self, links, blocks) -> tuple:
        """Per block of ``blocks``: its size k and its groups of joints that move points in common,
        as (their joints, their place in the block (None: the whole block), the weights C) of
        :class:`_Structure`'s ``blocks``."""
        key = (tuple(links), tuple(tuple(int(j) for j in b) for b in blocks))
        if key not in self._layouts:
            st = self._points_structure(links)
            owner = np.full(self.n, -1)
            for i, b in enumerate(blocks):
                owner[np.asarray(b, dtype=int)] = i
            layout = [(len(b), []) for b in blocks]
            for sel, _, C in st.blocks:
                joints = np.arange(self.n)[sel]
                i = int(owner[joints[0]])
                b = np.asarray(blocks[i], dtype=int)
                local = np.searchsorted(b, joints)
                if np.any(owner[joints] != i) or np.any(b[local] != joints):
                    raise RobotConfigError("a block of joints splits joints that move points in common")
                if len(joints) == len(b):
                    place = None
                elif local[-1] - local[0] + 1 == len(local):
                    place = (slice(int(local[0]), int(local[-1]) + 1),) * 2
                else:
                    place = np.ix_(local, local)
                layout[i][1].append((sel, place, C))
            self._layouts[key] = tuple((k, tuple(groups)) for k, groups in layout)
        return self._layouts[key]

    def points_velocity(
        self, poses: Poses | None, x: np.ndarray, links, u: np.ndarray, xi: np.ndarray | None = None
    ) -> np.ndarray:
        """J_m u (B, N, 3) for points x (B, N, 3) on ``links`` and joint vectors u (B, n); the
        twists ``xi`` (6, B, n) of :meth:`twist_rows` may stand for ``poses``."""
        st = self._points_structure(links)
        B, N = x.shape[:2]
        xi = self.twist_rows(poses) if xi is None else xi
        tw = xi.transpose(1, 2, 0) * u[..., None]  # (B, n, 6)
        sw = (np.ascontiguousarray(tw.transpose(0, 2, 1)).reshape(B * 6, self.n) @ st.sign.T).reshape(B, 6, N)
        return sw[:, 3:].transpose(0, 2, 1) + cross(sw[:, :3].transpose(0, 2, 1), x)

    def points_project(
        self, poses: Poses | None, x: np.ndarray, links, f: np.ndarray, cols=None, xi: np.ndarray | None = None
    ) -> np.ndarray:
        """f_mᵀ J_m (B, N, n): each point's Jacobian projected on a direction f (B, N, 3); only
        the joints ``cols`` (c,) when given: (B, N, c). The twists ``xi`` (6, B, n) of
        :meth:`twist_rows` may stand for ``poses``."""
        st = self._points_structure(links)
        xi = self.twist_rows(poses) if xi is None else xi
        sign = st.sign
        if cols is not None:
            xi, sign = xi[:, :, cols], sign[:, cols]
        wrench = np.concatenate([cross(x, f), f], axis=2)  # ξ · (x × f, f) = f · (v + ω × x)
        return (wrench @ xi.transpose(1, 0, 2)) * sign

    def _points_structure(self, links) -> _Structure:
        key = tuple(links)
        if key not in self._structure:
            joint, _, _ = self.link_info(key)
            sign = self._anc[joint].astype(float) - self._anc[self.base_joint].astype(float)  # (N, n)
            D = sign != 0
            share = (D.T.astype(float) @ D) > 0
            nested = ~((D.T.astype(float) @ ~D) > 0).T  # nested[j, k]: D_k ⊆ D_j (k the deeper)
            if np.any(share & ~nested & ~nested.T):
                raise RobotConfigError("kinematic tree expected: two joints move overlapping point sets")
            sj = np.where(self._anc[self.base_joint], -1.0, 1.0)
            o, d = np.nonzero(share & nested & (~nested.T | np.tri(self.n, dtype=bool).T))  # one per pair
            C = np.zeros((self.n, self.n))
            C[o, d] = np.where(o == d, 0.5, 1.0) * sj[o] * sj[d]
            _, label = connected_components(share, directed=False)  # joints linked through shared points
            blocks = []
            for comp in np.unique(label[share.any(axis=0)]):  # the joints that move no point: none
                ix = np.flatnonzero(label == comp)
                if ix[-1] - ix[0] + 1 == len(ix):  # consecutive (a URDF's depth-first order): views
                    sel = slice(int(ix[0]), int(ix[-1]) + 1)
                    blocks.append((sel, (sel, sel), C[sel, sel]))
                else:
                    blocks.append((ix, np.ix_(ix, ix), C[np.ix_(ix, ix)]))
            self._structure[key] = _Structure(sign, D.astype(float), sj, share, tuple(blocks))
        return self._structure[key]

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


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a × b along the last axis (length 3) of broadcastable arrays: ``np.cross``'s arithmetic
    without its per-call overhead (the moved axes and the checks)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def _skew(a: np.ndarray) -> np.ndarray:
    """Cross-product matrix [a]× (3, 3) of a (3,)."""
    x, y, z = a
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def _cross3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product along axis 1 of component-major arrays (B, 3, n)."""
    return np.stack(
        [
            a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1],
            a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
            a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0],
        ],
        axis=1,
    )
