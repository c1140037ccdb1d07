"""Write the bundled sample logs (`make sample-data`): small, seeded simulator runs with /truth.

Usage: python scripts/make_sample_data.py sample_data

Each log is made with the public simulators (the same code as `diegocal simulate ...`); the
held-out kinematics log is the tail of the same session as the training log, so both share one
set of true sensor parameters (a held-out test must not change the sensors it tests).

The three ``*_hidden_*.h5`` logs each hide one effect for ``diegocal diagnose`` (``make demo``); the
pneumatic one keeps the streams of the right arm's chambers only (a lab logging one limb), which
keeps the file small and the demo quick.
"""

from __future__ import annotations

import subprocess
import sys
from dataclasses import replace
from pathlib import Path

from diegocal.io import load_log, save_log
from diegocal.robot import load_robot, resolve_robot_dir

KINEMATICS_SECONDS = 12.0  # 8 s to calibrate, 4 s held out
HELDOUT_SECONDS = 4.0
#: The right arm's chambers, kept in the pneumatic log that hides a valve delay.
ARM_CHAMBERS = ("r_shoulder_pitch", "r_shoulder_roll", "r_shoulder_yaw", "r_elbow")


def diegocal(*args: str) -> None:
    subprocess.run([sys.executable, "-m", "diegocal", *args, "--quiet"], check=True)


def main(out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    session = out / "_diego_session.h5"
    diegocal(
        "simulate",
        "kinematics",
        "--robot",
        "diego",
        "--duration",
        str(KINEMATICS_SECONDS),
        "--seed",
        "1",
        "-o",
        str(session),
    )
    log = load_log(session)
    split = log.n_samples - int(round(HELDOUT_SECONDS * (log.rate_hz or 100.0)))
    save_log(log.slice(0, split), out / "diego_kinematics.h5")
    save_log(log.slice(split, log.n_samples), out / "diego_kinematics_heldout.h5")
    session.unlink()
    diegocal(
        "simulate",
        "pneumatics",
        "--robot",
        "diego",
        "--duration",
        "8",
        "--seed",
        "1",
        "-o",
        str(out / "diego_pneumatics.h5"),
    )
    diegocal(
        "simulate",
        "dynamics",
        "--robot",
        "arm3",
        "--duration",
        "8",
        "--rate",
        "50",
        "--seed",
        "1",
        "--trajectory",
        "figure8-horizontal",
        "--effect",
        "position_friction:joint3",
        "--region",
        "joint3:1.3:1.6",  # inside the range the figure-eight visits (the default region is not)
        "-o",
        str(out / "arm3_dynamics.h5"),
    )
    hidden_effects(out)


def hidden_effects(out: Path) -> None:
    """One log per domain hiding one effect, for ``diegocal diagnose`` in ``make demo``."""
    diegocal(
        "simulate", "kinematics", "--robot", "finger", "--duration", "30", "--seed", "2",
        "--effect", "sensor_nonlinearity:fds", "-o", str(out / "finger_hidden_nonlinearity.h5"),
    )  # fmt: skip
    diegocal(
        "simulate", "dynamics", "--robot", "arm3", "--duration", "30", "--seed", "2",
        "--effect", "position_friction:joint3", "--region", "joint3:1.0:1.4",
        "-o", str(out / "arm3_hidden_friction.h5"),
    )  # fmt: skip
    full = out / "_diego_pneumatics_full.h5"
    diegocal(
        "simulate", "pneumatics", "--robot", "diego", "--duration", "20", "--seed", "2",
        "--effect", "valve_delay:r_elbow.flex", "-o", str(full),
    )  # fmt: skip
    log = load_log(full)
    specs = [c for c in load_robot(resolve_robot_dir("diego", None)).sensors.chambers if c.joint in ARM_CHAMBERS]
    chambers = [c.name for c in specs]
    pots = list(dict.fromkeys(c.volume_sensor for c in specs))
    streams = {
        "pressure": log.streams["pressure"].select(chambers),
        "valve": log.streams["valve"].select(chambers),
        "pots": log.streams["pots"].select(pots),
    }
    signals = {**log.truth.signals, "pressure": log.truth.signals["pressure"].select(chambers)}
    arm = replace(log, streams=streams, truth=replace(log.truth, signals=signals))
    save_log(arm, out / "diego_hidden_valve_delay.h5")
    full.unlink()


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "sample_data"))
