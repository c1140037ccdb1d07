"""The thesis's SGP experiments (ch. 3) on simulated robots: pendulum (§3.1.1/3.4.1), reaction
wheel (§3.4.2) and 3-link arm (§3.4.4). Each ``run_*`` returns per-cell scores; :func:`table`
prints them. ``bench/bench_sgp_experiments.py`` runs the full versions."""

from experiments.sgp.arm3 import ArmConfig, run_arm3
from experiments.sgp.common import METHODS, Score, aggregate, run_methods, table
from experiments.sgp.pendulum import PendulumConfig, run_pendulum
from experiments.sgp.reaction_wheel import WheelConfig, run_reaction_wheel

__all__ = [
    "METHODS",
    "ArmConfig",
    "PendulumConfig",
    "Score",
    "WheelConfig",
    "aggregate",
    "run_arm3",
    "run_methods",
    "run_pendulum",
    "run_reaction_wheel",
    "table",
]
