"""CLI: `diegocal simulate kinematics` (dynamics and pneumatics attach from their own modules)."""
