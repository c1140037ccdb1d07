"""The words diegocal's vocabularies are made of: causes of model error and their domains, and
what an effect's SIZE means. Plain data, no imports: the simulators, diagnose and the command
line's `--help` (which must load nothing heavy) all read them from here."""

#: Cause id -> domain, from DESIGN.md's diagnosis vocabulary, extended with the causes real
#: torque data asks for (issue #13): ``armature`` (rotor inertia, torque ∝ qdd), ``coupled_friction``
#: (a motor driving two joints, e.g. the TX40's wrist), ``torque_lag`` (the torque sensor lags).
VOCABULARY: dict[str, str] = {
    "link_offset": "kinematics",
    "sensor_nonlinearity": "kinematics",
    "backlash": "kinematics",
    "time_offset": "kinematics",
    "marker_slip": "kinematics",
    "marker_outliers": "kinematics",
    "swapped_labels": "kinematics",
    "coulomb_friction": "dynamics",
    "viscous_friction": "dynamics",
    "position_friction": "dynamics",
    "payload": "dynamics",
    "spring": "dynamics",
    "torque_offset": "dynamics",
    "armature": "dynamics",
    "coupled_friction": "dynamics",
    "torque_lag": "dynamics",
    "valve_delay": "pneumatics",
    "chamber_leak": "pneumatics",
    "supply_droop": "pneumatics",
    "pressure_offset": "pneumatics",
}

DOMAINS = ("kinematics", "dynamics", "pneumatics")

#: What ``--effect CAUSE:CHANNEL=SIZE`` sizes, per cause (the unit is the channel's: V is the pot's
#: reading unit, m a marker's). Without SIZE the ranges of :func:`diegocal.sim.kinematics.plan_effects` apply.
KINEMATIC_SIZE_UNITS = {
    "link_offset": "in m, the distance the joint's origin moves (random direction), so every marker it carries",
    "sensor_nonlinearity": "in V, the transfer curve's departure from linear at the ends of the pot's range",
    "backlash": "in V, the dead band's full width on the reading (which lags by up to half of it)",
    "time_offset": "in s, the mocap clock's shift (sign random; need not be whole samples)",
    "marker_slip": "in m, the distance the marker moves on its link",
    "marker_outliers": "in m, the distance of every faulty reading from its marker",
    "swapped_labels": "in m, the partner's mean distance (the marker nearest SIZE is the partner)",
}
