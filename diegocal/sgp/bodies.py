"""The dynamics causes whose columns are a link's body's: ``payload`` and ``link_inertia``.

A link's body is its parent joint's ten inertial parameters (m, m·c, the second moments about the
joint frame's origin, Pinocchio's order; eq. 3.30's w for one body): a payload adds to them, a
wrong URDF changes them; both enter the model as that body's block of the joint-torque regressor
(channel: the link). ``link_inertia`` is never proposed: it is the name a fitted payload takes when
its values are no body (:mod:`diegocal.diagnose.bodies`).
"""

from __future__ import annotations

import pinocchio as pin

from diegocal.errors import InputFileError
from diegocal.sgp.proposal import Proposal
from diegocal.terms import make_term

#: The causes whose columns are a link's body's ten inertial columns (channel: the link).
BODIES = ("payload", "link_inertia")


def body_columns(term, m, j, out):
    """The joint-torque regressor's ten columns (m, m·c, second moments; Pinocchio's order) of the
    body that carries the link (a point mass anywhere on it: moments in the parent joint's frame)."""
    model = m.robot.model
    frame = next((f for f in model.frames if f.name == term.channel), None)
    if frame is None or frame.parentJoint == 0:
        raise InputFileError(f"{term.cause}: {term.channel!r} is not a moving link of robot {m.robot.name!r}")
    i = frame.parentJoint - 1  # the body's block of ten columns
    data = model.createData()
    for t in range(m.q.shape[0]):
        Y = pin.computeJointTorqueRegressor(model, data, m.q[t], m.qd[t], m.qdd[t]).reshape(model.nv, -1)
        out[t] = Y[:, 10 * i : 10 * i + 10]  # (a one-joint robot's comes back flat)


def payloads(cause: str, ctx) -> list[Proposal]:
    """A point mass on each moving link, where the rigid body is the URDF's (nominal inertias):
    an identified rigid body already fits a link's inertial parameters."""
    if ctx.inertia != "nominal":
        return []
    return [Proposal(make_term(cause, link)) for link in payload_links(ctx.robot)
            if not any((body, link) in ctx.have for body in BODIES)]  # a link_inertia there too


def restated_only(cause: str, ctx) -> list[Proposal]:
    """None: ``link_inertia`` is a fitted payload's other name (:mod:`diegocal.diagnose.bodies`),
    never a candidate of its own (the same columns)."""
    return []


def payload_links(robot) -> tuple[str, ...]:
    """The moving links a payload may sit on: per joint, the first body frame it carries (the
    frames of one joint share its inertial columns, so one of them stands for all)."""
    out, seen = [], set()
    for f in robot.model.frames:
        if f.type == pin.FrameType.BODY and f.parentJoint > 0 and f.parentJoint not in seen:
            seen.add(f.parentJoint)
            out.append(f.name)
    return tuple(out)
