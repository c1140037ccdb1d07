"""Write the bundled sample logs (`make sample-data`): small, seeded simulator runs with /truth.

Usage: python scripts/make_sample_data.py sample_data

Each log is made with the public simulators (the same code as `diegocal simulate ...`); the
held-out kinematics log is the tail of the same session as the training log, so both share one
set of true sensor parameters (a held-out test must not change the sensors it tests).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from diegocal.io import load_log, save_log

KINEMATICS_SECONDS = 12.0  # 8 s to calibrate, 4 s held out
HELDOUT_SECONDS = 4.0


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
        "-o",
        str(out / "arm3_dynamics.h5"),
    )


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "sample_data"))
