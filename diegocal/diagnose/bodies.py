"""A payload whose fitted values no body can have: the link's own inertias are wrong.

With the URDF's inertias kept (``diagnose --inertia nominal``), a ``payload``'s ten columns are its
link's body's block of the joint-torque regressor (eq. 3.30): they fit any error in that link's
inertial parameters, of which an added mass is one kind. When the fitted values are no body at all
(a mass below zero, second moments too small for the mass and first moment, a centre of mass
beyond the robot), naming a payload would put a mass where there is none; the finding is
``link_inertia`` instead, the same columns under the name that says what they show.
"""

from __future__ import annotations

import math

from diegocal.terms import Term, make_term

#: A payload is no body when it fails even with each of its parameters this many standard errors
#: in the body's favour (a point mass sits on the bound of :func:`impossible_body`).
BODY_Z = 3.0
#: How far out a payload's centre of mass may lie, in multiples of the robot's extent from its
#: joint (:meth:`~diegocal.robot.model.Robot.extent`): a tool held out as far again.
REACH = 2.0


def impossible_body(parameters: dict, z: float, reach: float = math.inf) -> str:
    """Why ten inertial parameters (``parameters``: name → (value, standard error), the payload
    cause's names) cannot be a body, in words ("" when they can be). A body of mass m whose first
    moment about the joint is h = m·c has, about the joint, second moments I = I_c + (|h|²·1 −
    h hᵀ)/m with I_c ⪰ 0 about its centre of mass, so each diagonal entry must reach
    (|h|² − h_i²)/m, and its centre of mass, |h|/m from the joint, must lie within ``reach`` (m).
    Judged with every parameter moved ``z`` standard errors in the body's favour (I up, |h| down,
    m up). Where the mass is not identified (its value means nothing) only I_ii ≥ 0 is judged, and
    nothing more where it is not positive (:func:`restate` says so first)."""
    value = {k: v for k, (v, _) in parameters.items()}
    se = {k: s if math.isfinite(s) else math.inf for k, (_, s) in parameters.items()}
    for a in "xyz":  # whatever the mass: I ⪰ 0 about any point
        if value[f"I_{a}{a}"] + z * se[f"I_{a}{a}"] < 0:
            return f"its second moment I_{a}{a} is below zero ({value[f'I_{a}{a}']:.3g} kg·m²)"
    if not math.isfinite(se["mass"]):
        return ""
    mass = value["mass"] + z * se["mass"]
    if mass <= 0:
        return ""
    # a first moment the torques do not fix may be 0: |h| down as far as it goes
    h2 = {a: max(abs(value[f"mc_{a}"]) - z * se[f"mc_{a}"], 0.0) ** 2 if se[f"mc_{a}"] < math.inf else 0.0
          for a in "xyz"}
    c = math.sqrt(sum(h2.values())) / mass
    if c > reach:
        return (f"its centre of mass would lie at least {c:.3g} m from the joint, beyond the robot's extent "
                f"from it ({reach:.3g} m)")
    for a in "xyz":
        need = (sum(h2.values()) - h2[a]) / mass
        if value[f"I_{a}{a}"] + z * se[f"I_{a}{a}"] < need - 1e-9 * need:  # a point mass sits on it
            return (f"a body of {value['mass']:.3g} kg with its centre of mass {c:.3g} m from the joint needs "
                    f"I_{a}{a} ≥ {need:.3g} kg·m², the fit gives {value[f'I_{a}{a}']:.3g}")
    return ""


def restate(term: Term, extent: float) -> tuple[Term, str] | None:
    """``link_inertia`` on the link, with why in words, for a fitted ``payload`` that is no body
    (:func:`impossible_body` within :data:`REACH` × ``extent`` m of its joint, or a mass more than
    :data:`BODY_Z` standard errors below zero); None for a body and for any other cause."""
    if term.cause != "payload":
        return None
    body = {p.name: (p.value, p.stderr) for p in term.parameters}
    mass, se = body["mass"]
    if math.isfinite(se) and mass < -BODY_Z * se:
        why = f"its mass is below zero ({mass:.3g} ± {se:.2g} kg)"
    else:
        why = impossible_body(body, BODY_Z, REACH * extent)
    if not why:
        return None
    return make_term("link_inertia", term.channel), f"fitted as a payload, {why}: the link's own inertias are wrong"
