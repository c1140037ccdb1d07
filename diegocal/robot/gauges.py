"""Gauge freedoms of kinematic calibration: joint zeros that markers cannot fix.

STAC (thesis §2.3-2.4, eq. 2.21) estimates the joint angles of every frame together with the pot
gains and biases, the marker positions ``d_m`` in their link frames and the mocap frame (R, T0).
Two structures make a joint's zero unobservable from the markers, whatever the data; each
shifts ``q_k`` by δ in every frame and the bias of every pot reading joint k by
``-gain · ∂s/∂q_k · δ``, and leaves every prediction unchanged:

* **leaf gauge** — every marker the joint moves (relative to the base link) sits on one link next
  to the joint, the one away from the base (its child link; its parent link when the joint is
  upstream of a base link that is not the URDF root): moving those markers back about (along)
  its axis, ``d -> Rot(a, -δ) d``, absorbs the offset (always the case for the last joint of a
  chain);
* **root gauge** — the joint moves every marker and its axis is fixed in the base frame (the
  base hangs from the world and every joint between them is prismatic, along the axis of a
  revolute joint: a robot's lift carrying its arm's first joint): rotating the mocap frame about
  that axis, ``(R, T0)``, absorbs the offset; for a prismatic joint, shifting it along the axis.

Both need every pot that depends on the joint to be linear in q (rotary, encoder, tendon): a
linear pot spanning the joint (eq. 2.19-2.20) measures a length that an offset changes
non-uniformly, which breaks the gauge. A calibration must fix one bias per gauge joint (a rotary
or encoder pot reading only that joint is the natural choice) or compare biases modulo these
directions. The thesis does not discuss them. tests/robot checks, on diego, finger and a small
moving-base robot, that the full calibration Jacobian loses exactly these directions.
"""

from __future__ import annotations

import numpy as np

from diegocal.robot.batch import BatchKinematics
from diegocal.robot.model import Robot


def axis_fixed_in_base(kin, k: int) -> bool:
    """Whether joint ``k``'s motion is the same in the base frame whatever the other joints do:
    every joint upstream of it is prismatic (and, for a revolute k, slides along k's axis line).
    ``kin`` is the robot's :class:`diegocal.robot.batch.BatchKinematics` (its base hangs from the
    world)."""
    up = [j for j in np.flatnonzero(kin._anc[k + 1]) if j != k]
    if not all(kin.prismatic[j] for j in up):
        return False
    if kin.prismatic[k] or not up:
        return True
    axis = kin.joint_poses(np.zeros((1, kin.n))).axis[0]
    return all(np.linalg.norm(np.cross(axis[j], axis[k])) < 1e-9 for j in up)


def _upstream(model, k: int, joint: int) -> bool:
    """Is joint ``k`` on the path from the root to ``joint`` (Pinocchio ids, inclusive)?"""
    return k in list(model.supports[joint])


def _moves(robot: Robot, k: int, joint: int) -> bool:
    """Does joint ``k`` move a frame attached to ``joint`` relative to the base link?"""
    base_joint = robot.model.frames[robot.base_frame].parentJoint
    return _upstream(robot.model, k, joint) != _upstream(robot.model, k, base_joint)


def spanned_by_linear_pot(robot: Robot, pots=None) -> np.ndarray:
    """(n,) bool, in :attr:`Robot.joint_names` order: joints that some linear pot of ``pots``
    (default: every pot of the robot) spans, its two anchors on either side of the joint. Such a
    joint's zero is no gauge: the anchors' distance (eq. 2.19-2.20) changes non-uniformly with it."""
    model = robot.model
    pots = robot.sensors.pots if pots is None else pots
    out = np.zeros(robot.n_joints, dtype=bool)
    for p in pots:
        if p.kind != "linear":
            continue
        ja, jb = (model.frames[robot.frame_id(a.link)].parentJoint for a in p.anchors)
        for k in range(1, model.njoints):
            out[k - 1] |= _upstream(model, k, ja) != _upstream(model, k, jb)
    return out


def gauge_joints(robot: Robot) -> tuple[str, ...]:
    """Names of the joints whose zero is a gauge freedom of marker-based calibration.

    Returns
    -------
    tuple of joint names, in :attr:`Robot.joint_names` order (empty when there are no markers).
    """
    model = robot.model
    kin = BatchKinematics(robot)
    marker_joint = [model.frames[robot.frame_id(m.link)].parentJoint for m in robot.sensors.markers]
    if not marker_joint:
        return ()
    base_joint = model.frames[robot.base_frame].parentJoint
    spanned = spanned_by_linear_pot(robot)
    out = []
    for k in range(1, model.njoints):
        moved = [j for j in marker_joint if _moves(robot, k, j)]
        if not moved or spanned[k - 1]:
            continue
        far_side = model.parents[k] if _upstream(model, k, base_joint) else k
        leaf = all(j == far_side for j in moved)
        root = base_joint == 0 and len(moved) == len(marker_joint) and axis_fixed_in_base(kin, k - 1)
        if leaf or root:
            out.append(robot.joint_names[k - 1])
    return tuple(out)


def gauge_axes(robot: Robot, joints) -> dict[str, tuple[str, np.ndarray]]:
    """Markers placed in a revolute leaf gauge: marker name -> (joint, its axis in the marker's
    link frame, a unit vector), for the leaf-gauge joints ``joints`` (names).

    A fit that fixes such a joint's zero places the markers of its far-side link turned about its
    axis by whatever offset that leaves (d -> Rot(a, -δ) d): of a difference of two of their
    positions (a slipped marker's move) only the length and the component along ``a`` are the
    data's. A prismatic joint's gauge shifts them along its axis, which no difference sees."""
    out: dict = {}
    if not joints:
        return out
    model, kin = robot.model, BatchKinematics(robot)
    base_joint = model.frames[robot.base_frame].parentJoint
    for name in joints:
        k = robot.joint_names.index(name) + 1
        if kin.prismatic[k - 1]:
            continue
        axis = kin.local_axis[k - 1]
        far_side = k
        if _upstream(model, k, base_joint):  # the gauge turns the parent link's markers
            far_side, axis = model.parents[k], kin.place_R[k - 1] @ axis
        for m in robot.sensors.markers:
            frame = model.frames[robot.frame_id(m.link)]
            if frame.parentJoint == far_side:
                a = np.asarray(frame.placement.rotation).T @ axis
                out[m.name] = (name, a / np.linalg.norm(a))
    return out
