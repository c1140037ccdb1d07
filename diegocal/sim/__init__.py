"""Data generators with ground truth in ``/truth`` and injectable, named effects."""

from diegocal.sim.effects import (
    VOCABULARY,
    EffectError,
    EffectRequest,
    SimOptionError,
    check_channel,
    check_effects,
    effect_record,
    parse_effect,
    parse_effects,
)
from diegocal.sim.kinematics import KinematicsOptions, simulate_kinematics

__all__ = [
    "VOCABULARY",
    "EffectError",
    "EffectRequest",
    "KinematicsOptions",
    "SimOptionError",
    "check_channel",
    "check_effects",
    "effect_record",
    "parse_effect",
    "parse_effects",
    "simulate_kinematics",
]
