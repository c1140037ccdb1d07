"""A robot: its URDF loaded through Pinocchio plus its sensors, and the kinematics the observation
models need, vectorised over frames.

Conventions. ``q`` is float64 of shape (T, n) with columns in :attr:`Robot.joint_names` order
(Pinocchio's joint order; rad for revolute joints, m for prismatic). Positions are expressed in
the frame of ``base_link`` (the link the mocap frame is rigidly fixed to, thesis §2.5.1), so a
point's position is ``base_T_world @ world_T_link @ xyz``.
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from diegocal.errors import OptionError, RobotConfigError, UnknownNameError
from diegocal.io import load_yaml
from diegocal.io.log import JOINT_STREAMS
from diegocal.io.urdf import is_xacro
from diegocal.robot.sensors import SensorConfig, parse_sensors
from diegocal.robot.urdf import load_urdf, reduce_model, root_link, sensor_joints

#: The bundled robots shipped with the package's source tree.
BUNDLED_ROBOTS = Path(__file__).resolve().parents[2] / "robots"


@dataclass(frozen=True)
class PointSet:
    """Points fixed on links: ``links`` (N,) names and ``xyz`` (N, 3) metres in each link frame."""

    links: tuple[str, ...]
    xyz: np.ndarray


#: A log channel of a joint stream this similar (difflib ratio) to a joint of the URDF that the log
#: does not name is taken for a misspelling of it (``elbw``/``elbow`` 0.89), below for another
#: device's channel (``gripper_motor``/``gripper_joint`` 0.77).
TYPO_CUTOFF = 0.8

#: Pinocchio's short names of the one-DoF prismatic joint models.
PRISMATIC_KINDS = ("PX", "PY", "PZ", "PrismaticUnaligned")


class Robot:
    """A kinematic tree (Pinocchio model) with its sensors.

    Parameters
    ----------
    model : pinocchio.Model
        Only one-DoF joints (revolute, prismatic) are accepted: q and qd have the same size
        (:func:`load_robot` locks or converts the others, :mod:`diegocal.robot.urdf`).
    sensors : SensorConfig
    name : str
    directory : Path or None
    locked : {joint: configuration} of the URDF's joints held still in ``model``
    source : the directory or URDF file it was loaded from (default: ``directory``)
    continuous : names of the joints that are continuous in the URDF: the model gives them the
        limits ±π (:mod:`diegocal.robot.urdf`), but they turn without end, so fits must not clip
        their angles to those limits (a wrist that has turned once more reads 2π further on)

    ``points``, ``points_jacobian`` and ``link_poses`` work on a Pinocchio ``Data`` of their own
    per call, so one Robot may serve several threads (``--jobs``); ``self.data`` is a spare one
    for callers' own Pinocchio calls.
    """

    def __init__(
        self,
        model: pin.Model,
        sensors: SensorConfig,
        name: str,
        directory: Path | None = None,
        locked: dict | None = None,
        source: Path | None = None,
        continuous=(),
    ):
        for j in range(1, model.njoints):
            if model.joints[j].nq != 1 or model.joints[j].nv != 1:
                raise RobotConfigError(
                    f"joint {model.names[j]!r} has {model.joints[j].nq} position coordinates; only "
                    "one-DoF joints are supported (load_robot locks or converts the others)"
                )
        self.model = model
        self.data = model.createData()
        self.sensors = sensors
        self.name = name
        self.directory = directory
        #: joints of the URDF held still in this model, with their configuration (see .urdf)
        self.locked: dict = dict(locked or {})
        #: where the robot was loaded from: its directory, or the URDF file itself
        self.source: Path | None = source if source is not None else directory
        self.joint_names: tuple[str, ...] = tuple(model.names[1:])
        self._joint_index = {n: i for i, n in enumerate(self.joint_names)}
        #: joints of ``model`` that are continuous in the URDF (no limit on their angle)
        self.continuous: frozenset = frozenset(continuous) & frozenset(self.joint_names)
        self.lower = np.array(model.lowerPositionLimit, dtype=float)
        self.upper = np.array(model.upperPositionLimit, dtype=float)
        if not model.existFrame(sensors.base_link):
            raise RobotConfigError(
                f"sensors.yaml: base_link {sensors.base_link!r} is not a link of robot {name!r}"
            )
        self.base_frame = self.frame_id(sensors.base_link)
        self._check_sensor_names()

    def with_model(self, model: pin.Model, sensors: SensorConfig | None = None) -> Robot:
        """The same robot (name, directory, source, locked and continuous joints) with another
        Pinocchio model of the same joints, or other sensors: a variant with shifted joint origins
        or added markers."""
        return Robot(
            model,
            self.sensors if sensors is None else sensors,
            self.name,
            self.directory,
            locked=self.locked,
            source=self.source,
            continuous=self.continuous,
        )

    @property
    def reference(self) -> str:
        """How a log names this robot (its ``robot`` attribute): the name of a bundled robot,
        else the absolute path of its directory (or URDF file), which ``--robot`` defaults to."""
        if self.source is None:
            return self.name
        source = Path(self.source).resolve()
        if source.parent == BUNDLED_ROBOTS.resolve():
            return source.name
        return str(source)

    # ------------------------------------------------------------------ names
    @property
    def n_joints(self) -> int:
        return len(self.joint_names)

    @property
    def prismatic_joints(self) -> frozenset:
        """Names of the prismatic joints (their coordinate is in m, their effort a force in N)."""
        kinds = {n: self.model.joints[self.model.getJointId(n)].shortname() for n in self.joint_names}
        return frozenset(n for n, k in kinds.items() if k.replace("JointModel", "") in PRISMATIC_KINDS)

    def joint_index(self, name: str) -> int:
        try:
            return self._joint_index[name]
        except KeyError:
            raise UnknownNameError(f"robot {self.name!r} has no joint {name!r}") from None

    def frame_id(self, link: str) -> int:
        """Pinocchio frame id of a link (its BODY frame: a joint may share the link's name)."""
        if self.model.existFrame(link, pin.FrameType.BODY):
            return self.model.getFrameId(link, pin.FrameType.BODY)
        if not self.model.existFrame(link):
            raise UnknownNameError(f"robot {self.name!r} has no link {link!r}")
        return self.model.getFrameId(link)

    def _check_sensor_names(self) -> None:
        for p in self.sensors.pots:
            try:
                for j in p.joints:
                    if j in self.locked:
                        raise UnknownNameError(f"joint {j!r} is locked in sensors.yaml")
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
    def _point_chain(self, points: PointSet) -> tuple[list[int], np.ndarray, np.ndarray]:
        """Per point: its frame id, its ``xyz`` (N, 3) in that frame, m, and the (N, n) mask of
        the joints that move it (its support, Pinocchio order)."""
        fids = self._point_frames(points)
        model = self.model
        mask = np.zeros((len(fids), self.n_joints))
        for k, f in enumerate(fids):
            mask[k, [i - 1 for i in model.supports[model.frames[f].parentJoint] if i > 0]] = 1.0
        return fids, np.asarray(points.xyz, dtype=float).reshape(-1, 3), mask

    @staticmethod
    def _world_points(data: pin.Data, fids: list[int], xyz: np.ndarray) -> np.ndarray:
        """World positions (N, 3) from ``data.oMf`` (frame placements already updated)."""
        oMf = data.oMf
        return np.array([oMf[f].act(x) for f, x in zip(fids, xyz, strict=True)]).reshape(-1, 3)

    def points(self, q, points: PointSet) -> np.ndarray:
        """Positions of link-fixed points in the base frame: ``base_T_world @ world_T_link @ xyz``.

        Returns
        -------
        ndarray of shape (T, N, 3), metres.
        """
        q = self.check_q(q)
        fids, xyz, _ = self._point_chain(points)
        out = np.empty((q.shape[0], len(fids), 3))
        data = self.model.createData()  # per call: concurrent calls (threads) never share it
        for t in range(q.shape[0]):
            pin.framesForwardKinematics(self.model, data, q[t])
            base = data.oMf[self.base_frame]
            out[t] = (self._world_points(data, fids, xyz) - base.translation) @ base.rotation
        return out

    def points_jacobian(self, q, points: PointSet) -> tuple[np.ndarray, np.ndarray]:
        """Positions and position Jacobians of link-fixed points, in the base frame.

        Thesis eq. (2.23) through Pinocchio's joint Jacobians: ``data.J`` holds every joint's
        motion axis as a spatial velocity [v_O; ω] at the world origin, so a point at p (world)
        moved by joint i has ∂p/∂q_i = v_O,i + ω_i × p = (J_v − [p]× J_ω)_i, for the joints that
        support its link only. In the base frame, x = R_bᵀ (p − p_b): when joints also move the
        base link (the base is not the URDF root) ∂x/∂q = R_bᵀ (∂p/∂q − ∂p_b/∂q + [p − p_b]× J_ω,b).

        Returns
        -------
        x : ndarray of shape (T, N, 3), metres
        J : ndarray of shape (T, N, 3, n), metres per rad (per metre for prismatic joints)
        """
        q = self.check_q(q)
        fids, xyz, mask = self._point_chain(points)
        model, data = self.model, self.model.createData()
        base_joint = model.frames[self.base_frame].parentJoint
        base_mask = np.zeros(self.n_joints)
        base_mask[[i - 1 for i in model.supports[base_joint] if i > 0]] = 1.0
        x = np.empty((q.shape[0], len(fids), 3))
        jac = np.empty((q.shape[0], len(fids), 3, self.n_joints))
        for t in range(q.shape[0]):
            J = pin.computeJointJacobians(model, data, q[t])  # (6, n), world frame; runs FK
            pin.updateFramePlacements(model, data)
            lin, ang = J[:3], J[3:]
            pw = self._world_points(data, fids, xyz)
            Jp = (lin - _cross_columns(pw, ang)) * mask[:, None, :]
            base = data.oMf[self.base_frame]
            if base_joint > 0:
                Jb_ang = ang * base_mask
                Jb_lin = (lin - _cross_columns(base.translation[None], ang)[0]) * base_mask
                Jp = Jp - Jb_lin + _cross_columns(pw - base.translation, Jb_ang)
            x[t] = (pw - base.translation) @ base.rotation
            jac[t] = base.rotation.T @ Jp
        return x, jac

    def link_poses(self, q, links) -> tuple[np.ndarray, np.ndarray]:
        """Rotation (T, L, 3, 3) and translation (T, L, 3) of each link in the base frame."""
        q = self.check_q(q)
        fids = [self.frame_id(link) for link in links]
        rot = np.empty((q.shape[0], len(fids), 3, 3))
        pos = np.empty((q.shape[0], len(fids), 3))
        data = self.model.createData()
        for t in range(q.shape[0]):
            pin.framesForwardKinematics(self.model, data, q[t])
            base = data.oMf[self.base_frame]
            for k, fid in enumerate(fids):
                rel = base.actInv(data.oMf[fid])
                rot[t, k] = rel.rotation
                pos[t, k] = rel.translation
        return rot, pos

    def extent(self, link: str) -> float:
        """m, the farthest any frame or body's centre of mass of the robot lies from ``link``'s
        joint at :meth:`neutral`: the scale of how far from that joint a carried load could sit."""
        model, data = self.model, self.model.createData()
        pin.framesForwardKinematics(model, data, self.neutral())
        joint = data.oMi[model.frames[self.frame_id(link)].parentJoint].translation
        points = [f.translation for f in data.oMf]
        points += [data.oMi[j].act(model.inertias[j].lever) for j in range(1, model.njoints)]
        return float(max(np.linalg.norm(p - joint) for p in points))

    def _base_is_fixed(self) -> bool:
        """True when no joint moves the base link (it hangs from the world, §2.5.1)."""
        return self.model.frames[self.base_frame].parentJoint == 0


def _cross_columns(p: np.ndarray, a: np.ndarray) -> np.ndarray:
    """p_k × a_i for points p (N, 3) and columns a (3, n): (N, 3, n), i.e. [p_k]× a."""
    p = p[:, :, None]
    return np.stack(
        (
            p[:, 1] * a[2] - p[:, 2] * a[1],
            p[:, 2] * a[0] - p[:, 0] * a[2],
            p[:, 0] * a[1] - p[:, 1] * a[0],
        ),
        axis=1,
    )


def shift_joint_origins(model: pin.Model, offsets: dict) -> pin.Model:
    """A copy of ``model`` whose named joints' origins are translated by (3,) m vectors, each in
    its parent joint's frame (a link whose geometry differs from the URDF: ``link_offset``)."""
    model = pin.Model(model)
    for joint, d in offsets.items():
        jid = model.getJointId(joint)
        placement = model.jointPlacements[jid].copy()
        placement.translation = placement.translation + np.asarray(d, float)
        model.jointPlacements[jid] = placement
    return model


def perturb_joint_placements(model: pin.Model, deltas: dict) -> pin.Model:
    """A copy of ``model`` whose named joints' placements are composed with a small rigid motion:
    ``jointPlacement · SE3(exp(r), d)`` for joint -> (6,) [dx, dy, dz (m), rx, ry, rz (rad, a
    rotation vector)], both in the joint's own nominal frame, the one its axis is written in (the
    6-parameter per-joint deviation of geometric calibration: ``joint_geometry``)."""
    model = pin.Model(model)
    for joint, v in deltas.items():
        v = np.asarray(v, float)
        jid = model.getJointId(joint)
        model.jointPlacements[jid] = model.jointPlacements[jid] * pin.SE3(pin.exp3(v[3:]), v[:3])
    return model


def is_description(path) -> bool:
    """Whether ``path`` is a robot description file: a ``.urdf``, or a xacro (``.xacro``,
    ``.urdf.xacro``) that :func:`diegocal.io.urdf.urdf_text` expands to one."""
    path = Path(path)
    return path.is_file() and (path.suffix.lower() == ".urdf" or is_xacro(path))


def description_stem(path) -> str:
    """A description file's name without ``.urdf``/``.xacro``: ``arm`` for ``arm.urdf.xacro``."""
    name = Path(path).name
    for suffix in (".xacro", ".urdf"):
        if name.lower().endswith(suffix):
            name = name[: -len(suffix)]
    return name


def load_robot(source, joints=None) -> Robot:
    """Load a robot: a directory (``robot.urdf`` + ``sensors.yaml``, DESIGN.md) or, for dynamics
    alone, a URDF file or a directory with ``robot.urdf`` only (no sensors; the base link is the
    URDF's root). A xacro description (``.xacro``, ``.urdf.xacro``) is accepted wherever a URDF is,
    expanded with its default arguments (:func:`diegocal.io.urdf.urdf_text`).

    Any URDF Pinocchio loads is accepted; the model is reduced to the joints the sensors use plus
    ``joints`` (the joint names the data use, e.g. :func:`data_joints` of a log; None: not known),
    the others locked (:mod:`diegocal.robot.urdf`; :attr:`Robot.locked` says at what). Names in
    ``joints`` that are no joint of the URDF are skipped (the stream readers warn), unless one
    reads like a joint the data do not name (TYPO_CUTOFF): that is an UnknownNameError.
    """
    source = Path(source)
    if source.is_dir() and not (source / "sensors.yaml").exists() and (source / "robot.urdf").is_file():
        source = source / "robot.urdf"  # sensors.yaml omitted: dynamics alone (DESIGN.md)
    if is_description(source):
        urdf, directory = source, None
        loaded = load_urdf(urdf)
        sensors = SensorConfig(urdf.name, root_link(loaded.model), (), (), ())
    else:
        if not source.is_dir():
            raise RobotConfigError(f"{source}: robot directory not found")
        directory = source
        sensors_file = directory / "sensors.yaml"
        if not sensors_file.exists():
            raise RobotConfigError(f"{directory}: no sensors.yaml (and no robot.urdf)")
        sensors = parse_sensors(load_yaml(sensors_file), source=str(sensors_file))
        urdf = directory / sensors.urdf
        if not urdf.exists():
            raise RobotConfigError(f"{directory}: URDF {sensors.urdf!r} not found")
        loaded = load_urdf(urdf)
    model = loaded.model
    known = set(model.names[1:])
    named = set(joints or ())
    # a data channel that is no joint of the URDF (a gripper's motor) is left to the stream readers,
    # which leave it out with a warning; one that reads like a joint the data do not name is a
    # misspelling, which would lock that joint: an error
    for u in sorted(named - known):
        match = difflib.get_close_matches(u, sorted(known - named), n=1, cutoff=TYPO_CUTOFF)
        if match:
            raise UnknownNameError(
                f"log channel {u!r} of the joint streams (q, qd, qdd, tau) is not a joint of {urdf.name} — "
                f"did you mean {match[0]!r}?"
            )
    used = sensor_joints(model, sensors) | (named & known)
    keep = (used & known) or None  # nothing named: every one-DoF joint
    reduction = reduce_model(model, keep, sensors.locked)
    name = model.name or (directory.name if directory is not None else description_stem(urdf))
    return Robot(reduction.model, sensors, name=name, directory=directory, locked=reduction.locked, source=source,
                 continuous=loaded.continuous)


def data_joints(log) -> set[str]:
    """Channel names of a log's joint streams (q, qd, qdd, tau): the joints the data use."""
    return {n for s in JOINT_STREAMS if log.has(s) for n in log.streams[s].names}


def resolve_robot_dir(robot: str | Path | None, log_robot: str | None) -> Path:
    """The robot directory (or URDF file) a command should use (DESIGN.md: --robot defaults to the
    log's robot).

    ``robot`` is a directory, a URDF file (or xacro description) or the name of a bundled robot;
    ``None`` means the log's ``robot`` attribute (any of those).
    """
    if robot is not None and not str(robot).strip():
        raise OptionError("--robot is empty: give a robot directory, a URDF file or a bundled robot's name")
    if robot is None:
        if not log_robot:
            raise RobotConfigError("the log names no robot: pass --robot DIR")
        robot = log_robot
    path = Path(robot)
    if path.is_dir() or is_description(path):
        return path
    bundled = BUNDLED_ROBOTS / str(robot)
    if "/" not in str(robot) and bundled.is_dir():
        return bundled
    raise RobotConfigError(
        f"robot {str(robot)!r} not found (neither a directory, a URDF or xacro file nor a bundled robot in "
        f"{BUNDLED_ROBOTS})"
    )
