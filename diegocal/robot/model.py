"""A robot: its URDF loaded through Pinocchio plus its sensors, and the kinematics the observation
models need, vectorised over frames.

Conventions. ``q`` is float64 of shape (T, n) with columns in :attr:`Robot.joint_names` order
(Pinocchio's joint order; rad for revolute joints, m for prismatic). Positions are expressed in
the frame of ``base_link`` (the link the mocap frame is rigidly fixed to, thesis §2.5.1), so a
point's position is ``base_T_world @ world_T_link @ xyz``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from diegocal.errors import RobotConfigError, UnknownNameError
from diegocal.robot.sensors import SensorConfig, parse_sensors

#: The bundled robots shipped with the package's source tree.
BUNDLED_ROBOTS = Path(__file__).resolve().parents[2] / "robots"


@dataclass(frozen=True)
class PointSet:
    """Points fixed on links: ``links`` (N,) names and ``xyz`` (N, 3) metres in each link frame."""

    links: tuple[str, ...]
    xyz: np.ndarray


class Robot:
    """A kinematic tree (Pinocchio model) with its sensors.

    Parameters
    ----------
    model : pinocchio.Model
        Only one-DoF joints (revolute, prismatic) are accepted: q and qd have the same size.
    sensors : SensorConfig
    name : str
    directory : Path or None
    """

    def __init__(
        self, model: pin.Model, sensors: SensorConfig, name: str, directory: Path | None = None
    ):
        for j in range(1, model.njoints):
            if model.joints[j].nq != 1 or model.joints[j].nv != 1:
                raise RobotConfigError(
                    f"joint {model.names[j]!r} has {model.joints[j].nq} position coordinates; only "
                    "one-DoF joints are supported (declare continuous joints as revolute with "
                    "wide limits)"
                )
        self.model = model
        self.data = model.createData()
        self.sensors = sensors
        self.name = name
        self.directory = directory
        self.joint_names: tuple[str, ...] = tuple(model.names[1:])
        self._joint_index = {n: i for i, n in enumerate(self.joint_names)}
        self.lower = np.array(model.lowerPositionLimit, dtype=float)
        self.upper = np.array(model.upperPositionLimit, dtype=float)
        if not model.existFrame(sensors.base_link):
            raise RobotConfigError(
                f"sensors.yaml: base_link {sensors.base_link!r} is not a link of robot {name!r}"
            )
        self.base_frame = self.frame_id(sensors.base_link)
        self._check_sensor_names()

    # ------------------------------------------------------------------ names
    @property
    def n_joints(self) -> int:
        return len(self.joint_names)

    def joint_index(self, name: str) -> int:
        try:
            return self._joint_index[name]
        except KeyError:
            raise UnknownNameError(f"robot {self.name!r} has no joint {name!r}") from None

    def frame_id(self, link: str) -> int:
        if not self.model.existFrame(link):
            raise UnknownNameError(f"robot {self.name!r} has no link {link!r}")
        return self.model.getFrameId(link)

    def _check_sensor_names(self) -> None:
        for p in self.sensors.pots:
            try:
                for j in p.joints:
                    self.joint_index(j)
                for a in p.anchors or ():
                    self.frame_id(a.link)
            except UnknownNameError as exc:
                raise RobotConfigError(f"sensors.yaml: pot {p.name!r}: {exc}") from None
        for m in self.sensors.markers:
            try:
                self.frame_id(m.link)
            except UnknownNameError as exc:
                raise RobotConfigError(f"sensors.yaml: marker {m.name!r}: {exc}") from None
        pots = set(self.sensors.pot_names)
        for c in self.sensors.chambers:
            try:
                self.joint_index(c.joint)
            except UnknownNameError as exc:
                raise RobotConfigError(f"sensors.yaml: chamber {c.name!r}: {exc}") from None
            if c.volume_sensor not in pots and c.volume_sensor not in self._joint_index:
                raise RobotConfigError(
                    f"sensors.yaml: chamber {c.name!r}: volume_sensor {c.volume_sensor!r} "
                    "is neither a pot nor a joint"
                )

    # ------------------------------------------------------------------ checks
    def check_q(self, q) -> np.ndarray:
        """Coerce joint angles to float64 of shape (T, n)."""
        q = np.asarray(q, dtype=float)
        if q.ndim == 1:
            q = q[None, :]
        if q.ndim != 2 or q.shape[1] != self.n_joints:
            raise ValueError(f"q: expected shape (T, {self.n_joints}), got {q.shape}")
        return q

    def _point_frames(self, points: PointSet) -> list[int]:
        """Frame ids of the points' links, after checking ``xyz`` is (N, 3) for N links."""
        xyz = np.asarray(points.xyz)
        if xyz.shape != (len(points.links), 3):
            raise ValueError(f"points.xyz: expected ({len(points.links)}, 3), got {xyz.shape}")
        return [self.frame_id(link) for link in points.links]

    def neutral(self) -> np.ndarray:
        """A configuration inside the limits: 0 where allowed, else the middle of the range."""
        q = np.zeros(self.n_joints)
        outside = (q < self.lower) | (q > self.upper)
        q[outside] = 0.5 * (self.lower + self.upper)[outside]
        return q

    # ------------------------------------------------------------------ kinematics
    def points(self, q, points: PointSet) -> np.ndarray:
        """Positions of link-fixed points in the base frame.

        Returns
        -------
        ndarray of shape (T, N, 3), metres.
        """
        q = self.check_q(q)
        fids = self._point_frames(points)
        out = np.empty((q.shape[0], len(fids), 3))
        model, data = self.model, self.data
        for t in range(q.shape[0]):
            pin.framesForwardKinematics(model, data, q[t])
            base = data.oMf[self.base_frame]
            for k, fid in enumerate(fids):
                out[t, k] = base.actInv(data.oMf[fid].act(points.xyz[k]))
        return out

    def points_jacobian(self, q, points: PointSet) -> tuple[np.ndarray, np.ndarray]:
        """Positions and position Jacobians of link-fixed points, in the base frame.

        From Pinocchio's frame Jacobians (thesis eq. 2.23): for a point at r = R d on a frame with
        world Jacobian [J_v; J_ω] (LOCAL_WORLD_ALIGNED), ∂x/∂q = J_v − [r]× J_ω, then rotated
        into the base frame (minus the base's own motion when the base is not the root).

        Returns
        -------
        x : ndarray of shape (T, N, 3), metres
        J : ndarray of shape (T, N, 3, n), metres per rad
        """
        q = self.check_q(q)
        fids = self._point_frames(points)
        n = self.n_joints
        x = np.empty((q.shape[0], len(fids), 3))
        jac = np.empty((q.shape[0], len(fids), 3, n))
        model, data = self.model, self.data
        lwa = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        base_fixed = self._base_is_fixed()
        for t in range(q.shape[0]):
            pin.computeJointJacobians(model, data, q[t])
            pin.updateFramePlacements(model, data)
            base = data.oMf[self.base_frame]
            Rb = base.rotation
            if not base_fixed:
                Jb = pin.getFrameJacobian(model, data, self.base_frame, lwa)
            for k, fid in enumerate(fids):
                J6 = pin.getFrameJacobian(model, data, fid, lwa)
                r = data.oMf[fid].rotation @ points.xyz[k]
                pw = data.oMf[fid].translation + r
                Jw = J6[:3] - _skew(r) @ J6[3:]
                if not base_fixed:
                    # x_b = Rbᵀ (p_w − p_b): subtract the base point's velocity and the effect
                    # of the base's rotation, d(Rbᵀ) v = Rbᵀ [v]× ω_b
                    rel = pw - base.translation
                    Jw = Jw - Jb[:3] + _skew(rel) @ Jb[3:]
                x[t, k] = Rb.T @ (pw - base.translation)
                jac[t, k] = Rb.T @ Jw
        return x, jac

    def link_poses(self, q, links) -> tuple[np.ndarray, np.ndarray]:
        """Rotation (T, L, 3, 3) and translation (T, L, 3) of each link in the base frame."""
        q = self.check_q(q)
        fids = [self.frame_id(link) for link in links]
        rot = np.empty((q.shape[0], len(fids), 3, 3))
        pos = np.empty((q.shape[0], len(fids), 3))
        for t in range(q.shape[0]):
            pin.framesForwardKinematics(self.model, self.data, q[t])
            base = self.data.oMf[self.base_frame]
            for k, fid in enumerate(fids):
                rel = base.actInv(self.data.oMf[fid])
                rot[t, k] = rel.rotation
                pos[t, k] = rel.translation
        return rot, pos

    def _base_is_fixed(self) -> bool:
        """True when no joint moves the base link (it hangs from the world, §2.5.1)."""
        return self.model.frames[self.base_frame].parentJoint == 0


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def load_robot(directory) -> Robot:
    """Load ``robot.urdf`` + ``sensors.yaml`` from a robot directory (DESIGN.md)."""
    from diegocal.io import load_yaml

    directory = Path(directory)
    if not directory.is_dir():
        raise RobotConfigError(f"{directory}: robot directory not found")
    sensors_file = directory / "sensors.yaml"
    if not sensors_file.exists():
        raise RobotConfigError(f"{directory}: no sensors.yaml")
    sensors = parse_sensors(load_yaml(sensors_file), source=str(sensors_file))
    urdf = directory / sensors.urdf
    if not urdf.exists():
        raise RobotConfigError(f"{directory}: URDF {sensors.urdf!r} not found")
    try:
        model = pin.buildModelFromUrdf(str(urdf))
    except (RuntimeError, ValueError) as exc:
        raise RobotConfigError(
            f"{urdf}: Pinocchio cannot load it ({str(exc).splitlines()[0]})"
        ) from None
    return Robot(model, sensors, name=model.name or directory.name, directory=directory)


def resolve_robot_dir(robot: str | Path | None, log_robot: str | None) -> Path:
    """The robot directory a command should use (DESIGN.md: --robot defaults to the log's robot).

    ``robot`` is a directory or the name of a bundled robot; ``None`` means the log's ``robot``
    attribute, looked up in the bundled ``robots/`` folder.
    """
    if robot is None:
        if not log_robot:
            raise RobotConfigError("the log names no robot: pass --robot DIR")
        robot = log_robot
    path = Path(robot)
    if path.is_dir():
        return path
    bundled = BUNDLED_ROBOTS / str(robot)
    if bundled.is_dir():
        return bundled
    raise RobotConfigError(
        f"robot {str(robot)!r} not found (neither a directory nor a bundled robot in "
        f"{BUNDLED_ROBOTS})"
    )
