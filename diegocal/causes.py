"""The cause registry: every part a model is made of and every cause ``diagnose`` can name.

One table, plain data, no heavy imports (the command line's ``--help`` reads it). Each
:class:`Cause` says

- its **domain** (kinematics, dynamics, pneumatics; ``any`` for ``unexplained``),
- its **role**: ``baseline`` (a part of the domain's model before any diagnosis: a pot's transfer,
  a chamber's valve), ``term`` (a model error a diagnosis may name and add), ``fault`` (a data fault
  whose readings are written off or repaired), ``companion`` (fitted with the baseline where the
  data allow, never simulated as a hidden effect: a known limit of the model, such as the
  tick-averaged pressure sensors' lag, never a finding; ``joint_geometry``, a finding only where
  ``diagnose`` tests it, on static poses) or ``verdict`` (``unexplained``),
- what its **channel** names (a pot, a joint, a marker, a chamber, a link, the mocap clock),
- its named **parameters** with unit, bounds, start value and meaning (lmfit's ``Parameter``),
- whether it acts only in a **region** of a variable, and which **extra** facts it needs (a
  partner channel, a ratio),
- its plain-words **phrase**, used by reports and summaries.

How a cause enters a model is its domain's business (the behaviour modules
:mod:`diegocal.stac.terms`, :mod:`diegocal.sgp.terms`, :mod:`diegocal.pneumatic.terms`);
:mod:`diegocal.terms` builds terms from this table. Adding a cause is one entry here, its
behaviour in one of those modules, and its tests (docs/design.md, "Adding a cause").
"""

from __future__ import annotations

import difflib
import math
from dataclasses import dataclass

from diegocal.domains import DOMAIN_NAMES
from diegocal.errors import UnknownNameError

DOMAINS = DOMAIN_NAMES
ROLES = ("baseline", "term", "fault", "companion", "verdict")
INF = math.inf


@dataclass(frozen=True)
class ParamSpec:
    """One parameter of a cause: name, unit, bounds, start value, meaning (and where its bounds
    come from, ``note``). ``shape``: not the coefficient of a regressor column but a parameter of
    the column's shape (a velocity scale, a spring's rest angle), held while the linear ones are
    fitted and searched by the fit that adds the term: between its bounds where they are positive
    (in log space), else over the range the data give it (:mod:`diegocal.diagnose.dynamics_shapes`).
    ``nonnegative``: what it measures cannot be negative (a friction, a dead band, an inertia, a
    mass), though a linear fit may make it so: a value significantly below 0 says the term stands
    in for something else (:func:`unphysical`).
    ``earlier``: for a parameter added to a cause after files were written with it, the value
    such a file means (it may lack the parameter); None: every file has it."""

    name: str
    unit: str
    lower: float = -INF
    upper: float = INF
    start: float = 0.0
    meaning: str = ""
    note: str = ""
    shape: bool = False
    nonnegative: bool = False
    earlier: float | None = None


@dataclass(frozen=True)
class Cause:
    """One entry of the registry (see the module docstring).

    ``parameters`` empty with ``named_by_model`` True: the model names them when it is fitted
    (the rigid body's base parameters depend on the robot). ``region``: "none", "optional" or
    "required". ``extra``: keys a term of this cause must carry in ``extra`` from the start
    (facts its behaviour derives from the data, such as a pot curve's centre, are added when it
    is fitted); ``partner``: the name of the ``extra`` key that holds another channel;
    ``signed_by``: the variable (on the term's channel) whose sign the evidence residual is
    multiplied by: friction follows the direction of motion, and its mean residual over an angle the
    joint crosses both ways averages to nothing; ``shown_against``: the variable (on the term's
    channel) its evidence is drawn against where it has no region (friction near zero velocity:
    the velocity, which its shape is a function of).
    """

    id: str
    domain: str
    role: str
    channel: str
    parameters: tuple[ParamSpec, ...]
    phrase: str
    region: str = "none"
    extra: tuple[str, ...] = ()
    partner: str | None = None
    named_by_model: bool = False
    signed_by: str | None = None
    shown_against: str | None = None

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.parameters)

    @property
    def is_finding(self) -> bool:
        """Whether a diagnosis may report it (a term or a fault)."""
        return self.role in ("term", "fault")


def _p(name, unit, meaning, lower=-INF, upper=INF, start=0.0, note="", shape=False, nonnegative=False,
       earlier=None) -> ParamSpec:
    return ParamSpec(name, unit, lower, upper, start, meaning, note, shape, nonnegative, earlier)


def _positive(name, unit, meaning) -> ParamSpec:
    """A coefficient that cannot be negative (:attr:`ParamSpec.nonnegative`), fitted without bounds."""
    return _p(name, unit, meaning, nonnegative=True)


_XYZ = tuple(_p(a, "m", f"displacement along {a[1]}") for a in ("dx", "dy", "dz"))
#: A link body's inertial parameters after its mass (Pinocchio's order: about the joint frame).
_MOMENTS = (*(_p(f"mc_{a}", "kg·m", "first moment") for a in "xyz"),
            *(_p(f"I_{ab}", "kg·m²", "second moment") for ab in ("xx", "xy", "yy", "xz", "yz", "zz")))

#: Table 4.1 of the thesis; c2 > 0 and c7 > 0 are ours: they fix the sign conventions (s grows
#: with u, the rate r is positive) that §4.3 states in words ("r() > 0") but the table does not list.
C1 = _p("c1", "V", "valve-voltage origin (U_c + U_r)/2", 2.0, 8.0, 5.0, "Table 4.1")
C2 = _p("c2", "1/V", "valve-voltage scale B", 1e-3, INF, 1.0, "ours: > 0")
C3 = _p("c3", "1/V^3", "kink factor", -1.0, INF, 0.0, "Table 4.1")
C4 = _p("c4", "pu s", "ds/dvdot")
C5 = _p("c5", "1", "dr/dvdot")
C6 = _p("c6", "1", "volume-sensor scale", -0.98, 0.98, 0.0,
        "|c6| < 1 keeps 1 + c6 v' > 0 on the normalised travel v' in [-1, 1]")
C7 = _p("c7", "1/(s V)", "B of eq. (4.3): rate per volt", 1e-6, INF, 10.0, "ours: > 0")
C8 = _p("c8", "1", "rate asymmetry", -1.0, 1.0, 0.0, "Table 4.1")
C9 = _p("c9", "V", "leakage (L_c + L_r)/2", 1e-6, INF, 0.05, "Table 4.1: > 0")
#: The longest valve delay a chamber model (and diagnose's grid) considers, s.
MAX_DELAY_S = 0.1
#: The longest lag of the tick-averaged pressure sensors (one 10 ms tick, thesis §4.5), s.
MAX_SENSOR_LAG_S = 0.01
#: The longest torque-sensor time constant a torque_lag may take, s.
MAX_LAG_S = 0.5
#: The largest relative gain error a torque_gain may take (a sensor off by half is a fault, not a gain).
MAX_GAIN_ERROR = 0.5
#: The largest half-width a transmission_backlash may take, rad (a play of ±6° is a broken gear, not a backlash).
MAX_BACKLASH_RAD = 0.1
#: A coupled motor's smallest Coulomb smoothing, rad/s: tanh(v / 1e-4) is sign(v) but within
#: 1e-4 rad/s of rest (what files written before the smoothing existed mean)
MIN_SMOOTHING = 1e-4

_CAUSES = (
    # ------------------------------------------------------------------ kinematics (thesis ch. 2)
    Cause("pot_transfer", "kinematics", "baseline", "pot",
          (_p("gain", "V/rad", "reading per unit of the sensed length or angle (V/m for linear pots "
              "and tendons)"), _p("bias", "V", "reading at zero")),
          "the pot's linear transfer, reading = gain · s(q) + bias (eq. 2.18-2.20)"),
    Cause("marker_position", "kinematics", "baseline", "marker",
          (_p("x", "m", "position in its link's frame"), _p("y", "m", "position in its link's frame"),
           _p("z", "m", "position in its link's frame")),
          "the marker's position on its link", extra=("link",)),
    Cause("mocap_frame", "kinematics", "baseline", "markers",
          (_p("x", "m", "translation"), _p("y", "m", "translation"), _p("z", "m", "translation"),
           _p("rx", "rad", "rotation vector"), _p("ry", "rad", "rotation vector"),
           _p("rz", "rad", "rotation vector")),
          "the motion-capture frame relative to the base link"),
    Cause("link_offset", "kinematics", "term", "joint", _XYZ,
          "the joint's origin differs from the URDF"),
    Cause("joint_geometry", "kinematics", "companion", "joint",
          _XYZ + tuple(_p(a, "rad", f"rotation about {a[1]} (rotation vector)") for a in ("rx", "ry", "rz")),
          "the joint's origin and axis differ from the URDF (stac --geometry; diagnose on static poses)"),
    Cause("sensor_nonlinearity", "kinematics", "term", "pot",
          (_p("c2", "V", "quadratic departure at the ends of the range"),
           _p("c3", "V", "cubic departure at the ends of the range")),
          "the pot's transfer curve is not linear"),
    Cause("backlash", "kinematics", "term", "pot",
          (_p("half_width", "V", "half the dead band (> 0: the reading lags the link; < 0: it leads it, the pot "
              "reading the motor's side of the play, or a pot's own hysteresis)"),),
          "the pot lags by a dead band that depends on the direction of motion"),
    Cause("time_offset", "kinematics", "term", "markers", (_p("seconds", "s", "mocap clock shift"),),
          "the mocap and pot clocks are shifted"),
    Cause("marker_slip", "kinematics", "term", "marker", _XYZ,
          "the marker moved on its link during the session", region="required"),
    Cause("marker_outliers", "kinematics", "fault", "marker", (),
          "some marker readings are outliers (ghosts, reflections)"),
    Cause("swapped_labels", "kinematics", "fault", "marker", (),
          "two markers' labels are swapped in some frames", extra=("partner", "frames"), partner="partner"),
    # ------------------------------------------------------------------ dynamics (thesis ch. 3)
    Cause("rigid_body", "dynamics", "baseline", "robot", (),
          "the rigid body's base inertial parameters (eq. 3.30)", named_by_model=True),
    Cause("viscous_friction", "dynamics", "term", "joint",
          (_positive("viscous", "N·m·s/rad", "torque per unit velocity"),),
          "viscous friction missing from the model (a torque proportional to the velocity)", signed_by="qd"),
    Cause("coulomb_friction", "dynamics", "term", "joint",
          (_positive("coulomb", "N·m", "torque that follows the sign of the velocity"),),
          "Coulomb friction missing from the model (a torque that follows the sign of the velocity)",
          signed_by="qd"),
    Cause("stribeck_friction", "dynamics", "term", "joint",
          (_p("amplitude", "N·m", "torque at zero velocity beyond Coulomb's (> 0: static friction above "
              "Coulomb, Stribeck; < 0: a smooth, pre-sliding transition through zero velocity)"),
           _p("velocity_scale", "rad/s", "speed over which it decays, e^(−|qd|/scale)", 1e-3, 2.0, 0.02,
              shape=True)),
          "friction's shape near zero velocity (a Stribeck or smooth transition)", signed_by="qd",
          shown_against="qd"),
    Cause("load_friction", "dynamics", "term", "joint",
          (_positive("coefficient", "1", "friction torque per unit of the joint's load torque (|τ| sign(qd))"),),
          "friction that grows with the load the joint carries (a gear under torque)", signed_by="qd"),
    Cause("position_friction", "dynamics", "term", "joint",
          (_p("coulomb", "N·m", "Coulomb level inside the region, beyond the joint's own (< 0: less there)"),
           _p("viscous", "N·m·s/rad", "viscous coefficient inside the region, beyond the joint's own")),
          "friction confined to part of the joint's range", region="required", signed_by="qd"),
    Cause("spring", "dynamics", "term", "joint",
          (_p("stiffness", "N·m/rad", "torque per radian"),
           _p("rest_angle", "rad", "the angle at which the spring exerts no torque", shape=True, earlier=0.0)),
          "a spring (a torque proportional to the joint angle)"),
    Cause("torque_offset", "dynamics", "term", "joint", (_p("offset", "N·m", "constant torque"),),
          "a constant offset of the torque sensor"),
    Cause("armature", "dynamics", "term", "joint", (_positive("inertia", "kg·m²", "reflected rotor inertia"),),
          "rotor inertia (a torque proportional to the acceleration)"),
    Cause("coupled_friction", "dynamics", "term", "joint",
          (_positive("coulomb", "N·m", "Coulomb level of the shared motor"),
           _positive("viscous", "N·m·s/rad", "viscous coefficient of the shared motor"),
           _p("smoothing", "rad/s", "the motor's speed over which its Coulomb friction changes sign, "
              "tanh(v / smoothing)", MIN_SMOOTHING, 2.0, 0.02, shape=True, earlier=MIN_SMOOTHING)),
          "friction of a motor that drives both joints", extra=("partner", "ratio"), partner="partner",
          signed_by="qd"),
    Cause("payload", "dynamics", "term", "link",
          (_positive("mass", "kg", "mass"), *_MOMENTS), "an unmodelled mass on this link"),
    Cause("link_inertia", "dynamics", "term", "link",
          (_p("mass", "kg", "mass"), *_MOMENTS),
          "the URDF's inertial parameters of this link are wrong (no body added to it explains the difference)"),
    Cause("torque_lag", "dynamics", "term", "joint", (_p("lag", "s", "time constant", 0.0, MAX_LAG_S),),
          "the measured torque lags the motion"),
    Cause("torque_gain", "dynamics", "term", "joint",
          (_p("gain_error", "1", "the sensor's gain error: it reads (1 + gain_error) x the torque",
              -MAX_GAIN_ERROR, MAX_GAIN_ERROR),),
          "the torque sensor's gain (or the motor's torque constant) is off"),
    Cause("transmission_backlash", "dynamics", "term", "joint",
          (_p("half_width", "rad", "the play's half-width: the link follows the motor's angle (the log's) "
              "once the motor has taken up the gap", 0.0, MAX_BACKLASH_RAD),),
          "the joint's transmission has play: the link lags the motor's angle by up to a half-width"),
    # ------------------------------------------------------------------ pneumatics (thesis ch. 4)
    Cause("valve_steady_state", "pneumatics", "baseline", "chamber", (C1, C2, C3),
          "the valve's steady state, eq. (4.10a-c)"),
    Cause("volume_rate_steady", "pneumatics", "baseline", "chamber", (C4,),
          "the volume rate in the steady state, eq. (4.10c)"),
    Cause("valve_rate", "pneumatics", "baseline", "chamber", (C7, C8, C9),
          "the rate's dependence on the valve, eq. (4.9), (4.10d-e)"),
    Cause("volume_rate_rate", "pneumatics", "baseline", "chamber", (C5,),
          "the volume rate in the rate, eq. (4.10e)"),
    Cause("chamber_volume", "pneumatics", "baseline", "chamber", (C6,),
          "the chamber's volume in the rate's denominator, eq. (4.10e)"),
    Cause("sensor_lag", "pneumatics", "companion", "chamber",
          (_p("lag_s", "s", "lag of the tick-averaged sensors", 0.0, MAX_SENSOR_LAG_S),),
          "the tick-averaged pressure answers a fraction of a tick late (§4.5)"),
    Cause("flow_saturation", "pneumatics", "companion", "chamber",
          (_p("sat", "1", "flow saturation per half-span c_s", 0.0, 20.0),),
          "the ports' flow is choked far from equilibrium (eq. 4.1)"),
    Cause("valve_delay", "pneumatics", "term", "chamber",
          (_p("delay_s", "s", "valve delay", 0.0, MAX_DELAY_S),),
          "the pressure answers the valve command late"),
    Cause("chamber_leak", "pneumatics", "term", "chamber", (_p("leak", "1/s", "leak rate to the room", 0.0),),
          "air escapes the chamber when it is sealed"),
    Cause("supply_droop", "pneumatics", "term", "chamber",
          (_p("droop", "pu", "supply sag while the valve draws from it", 0.0),),
          "the supply pressure sags under high flow"),
    Cause("pressure_offset", "pneumatics", "term", "chamber", (_p("offset", "pu", "pressure-sensor offset"),),
          "the pressure sensor's zero drifted"),
    # ------------------------------------------------------------------ any domain
    Cause("unexplained", "any", "verdict", "channel", (),
          "structured residual that no term of the vocabulary explains", region="optional"),
)

#: Cause id -> :class:`Cause`, in the order above.
CAUSES: dict[str, Cause] = {c.id: c for c in _CAUSES}

#: Cause id -> domain, of the causes a diagnosis may name (terms and faults): DESIGN.md's vocabulary.
VOCABULARY: dict[str, str] = {c.id: c.domain for c in _CAUSES if c.is_finding}

#: What ``simulate kinematics --effect CAUSE:CHANNEL=SIZE`` sizes, per cause (the unit is the
#: channel's: V is the pot's reading unit, m a marker's).
KINEMATIC_SIZE_UNITS = {
    "link_offset": "in m, the distance the joint's origin moves (random direction), so every marker it carries",
    "sensor_nonlinearity": "in V, the transfer curve's departure from linear at the ends of the pot's range",
    "backlash": "in V, the dead band's full width on the reading (which lags by up to half of it)",
    "time_offset": "in s, the mocap clock's shift (sign random; need not be whole samples)",
    "marker_slip": "in m, the distance the marker moves on its link",
    "marker_outliers": "in m, the distance of every faulty reading from its marker",
    "swapped_labels": "in m, the partner's mean distance (the marker nearest SIZE is the partner)",
}


#: A dynamics parameter's unit on a prismatic joint (a slide: force, metres), from its unit on a
#: revolute one (the registry's); units of neither (s, 1) read the same on both.
SLIDE_UNITS = {"N·m·s/rad": "N·s/m", "N·m/rad": "N/m", "N·m": "N", "rad/s": "m/s", "rad": "m", "kg·m²": "kg"}


def slide_unit(unit: str) -> str:
    """``unit`` (a revolute joint's: N·m, rad, kg·m², ...) as it reads on a prismatic joint."""
    return SLIDE_UNITS.get(unit, unit)


def cause(name: str) -> Cause:
    """The registry entry of ``name``; an unknown name raises with the closest known ones."""
    try:
        return CAUSES[name]
    except KeyError:
        close = difflib.get_close_matches(str(name), CAUSES, n=3)
        hint = f" (did you mean {', '.join(close)}?)" if close else ""
        raise UnknownNameError(f"unknown cause {name!r}{hint}") from None


def search_end(name: str, parameter: str, value: float) -> ParamSpec | None:
    """The spec of cause ``name``'s ``parameter`` when ``value`` ends at the upper end of its search
    (within 0.1 % of a finite, positive upper bound: a torque sensor's lag of 0.5 s), where the data
    want more than the cause describes; None otherwise (or for a name the registry does not hold)."""
    entry = CAUSES.get(name)
    spec = next((p for p in entry.parameters if p.name == parameter), None) if entry is not None else None
    if spec is None or not math.isfinite(spec.upper) or spec.upper <= 0 or value < spec.upper * (1 - 1e-3):
        return None
    return spec


def unphysical(name: str, parameter: str, value: float, stderr: float, z: float) -> ParamSpec | None:
    """The spec of cause ``name``'s ``parameter`` when it cannot be negative (:attr:`ParamSpec.
    nonnegative`) and ``value`` lies more than ``z`` standard errors below 0; None otherwise, for a
    value whose standard error is unknown (a payload's mass the torques do not identify: its value
    means nothing) and for a name the registry does not hold."""
    entry = CAUSES.get(name)
    spec = next((p for p in entry.parameters if p.name == parameter), None) if entry is not None else None
    if spec is None or not spec.nonnegative or not (math.isfinite(stderr) and stderr > 0):
        return None
    return spec if value < -z * stderr else None


def causes_of(domain: str, *roles: str) -> tuple[str, ...]:
    """The ids of ``domain``'s causes with one of ``roles`` (every role when none is given), in
    registry order."""
    return tuple(c.id for c in _CAUSES if c.domain == domain and (not roles or c.role in roles))


def phrase(name: str) -> str:
    """The plain-words meaning of a cause ("" for a name the registry does not know)."""
    c = CAUSES.get(name)
    return c.phrase if c is not None else ""
