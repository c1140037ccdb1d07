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
* **root gauge** — the joint's axis is fixed in the base frame and the joint moves every marker:
  rotating the mocap frame about that axis, ``(R, T0)``, absorbs the offset.

Both need every pot that depends on the joint to be linear in q (rotary, encoder, tendon): a
linear pot spanning the joint (eq. 2.19-2.20) measures a length that an offset changes
non-uniformly, which breaks the gauge. A calibration must fix one bias per gauge joint (a rotary
or encoder pot reading only that joint is the natural choice) or compare biases modulo these
directions. The thesis does not discuss them. tests/robot checks, on diego, finger and a small
moving-base robot, that the full calibration Jacobian loses exactly these directions.
"""

from __future__ import annotations

from diegocal.robot.model import Robot


def _upstream(model, k: int, joint: int) -> bool:
    """Is joint ``k`` on the path from the root to ``joint`` (Pinocchio ids, inclusive)?"""
    return k in list(model.supports[joint])


def _moves(robot: Robot, k: int, joint: int) -> bool:
    """Does joint ``k`` move a frame attached to ``joint`` relative to the base link?"""
    base_joint = robot.model.frames[robot.base_frame].parentJoint
    return _upstream(robot.model, k, joint) != _upstream(robot.model, k, base_joint)


def gauge_joints(robot: Robot) -> tuple[str, ...]:
    """Names of the joints whose zero is a gauge freedom of marker-based calibration.

    Returns
    -------
    tuple of joint names, in :attr:`Robot.joint_names` order (empty when there are no markers).
    """
    model = robot.model
    marker_joint = [model.frames[robot.frame_id(m.link)].parentJoint for m in robot.sensors.markers]
    if not marker_joint:
        return ()
    base_joint = model.frames[robot.base_frame].parentJoint
    anchor_joints = [
        tuple(model.frames[robot.frame_id(a.link)].parentJoint for a in p.anchors)
        for p in robot.sensors.pots
        if p.kind == "linear"
    ]
    out = []
    for k in range(1, model.njoints):
        moved = [j for j in marker_joint if _moves(robot, k, j)]
        spanned = any(
            _upstream(model, k, ja) != _upstream(model, k, jb) for ja, jb in anchor_joints
        )
        if not moved or spanned:
            continue
        far_side = model.parents[k] if _upstream(model, k, base_joint) else k
        leaf = all(j == far_side for j in moved)
        root = model.parents[k] == base_joint and len(moved) == len(marker_joint)
        if leaf or root:
            out.append(robot.joint_names[k - 1])
    return tuple(out)
