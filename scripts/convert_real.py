"""Convert the real-robot recordings (TX40, TIAGo) to diegocal logs, and build their robot dirs.

    python scripts/convert_real.py OUTDIR [--data DIR] [--robots DIR]

writes OUTDIR/tx40.h5 and OUTDIR/tiago.h5 (q, qd, qdd, tau; conversions documented in
diegocal/io/real.py and shared/data/real/README.md) and (re)writes ROBOTS/tx40 (tx40.urdf as
is) and ROBOTS/tiago (a reduced URDF: torso_lift_joint and arm_1..7 move, every other joint of
tiago_hey5.urdf is fixed at its neutral value).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np
import pinocchio as pin

from diegocal.io import save_log, save_yaml, write_text
from diegocal.io.real import TIAGO_JOINTS, load_tiago, load_tx40, reduce_urdf

REPO = Path(__file__).resolve().parents[1]
DEFAULT_DATA = Path(os.environ.get("DIEGOCAL_REAL_DATA", REPO.parent / "shared" / "data" / "real"))


def build_robots(data: Path, robots: Path) -> dict:
    """robots/tx40 and robots/tiago from the recordings' URDFs; returns a few facts."""
    tx = robots / "tx40"
    tx.mkdir(parents=True, exist_ok=True)
    write_text(tx / "robot.urdf", (data / "tx40" / "tx40.urdf").read_text())
    save_yaml({"urdf": "robot.urdf", "base_link": "base_link", "pots": [], "markers": []},
              tx / "sensors.yaml")
    ti = robots / "tiago"
    frozen = reduce_urdf(data / "tiago" / "tiago_hey5.urdf", ti / "robot.urdf", TIAGO_JOINTS,
                         name="tiago")
    model = pin.buildModelFromUrdf(str(ti / "robot.urdf"))
    save_yaml({"urdf": "robot.urdf", "base_link": model.frames[1].name, "pots": [],
               "markers": []}, ti / "sensors.yaml")
    data_ = model.createData()
    pin.computeSubtreeMasses(model, data_)
    carried = float(data_.mass[model.getJointId("torso_lift_joint")])
    return {"tiago_frozen_joints": len(frozen), "tiago_movable": list(model.names[1:]),
            "tiago_torso_carried_mass_kg": carried}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("outdir", type=Path)
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA, help="shared/data/real")
    parser.add_argument("--robots", type=Path, default=REPO / "robots",
                        help="where robots/tx40 and robots/tiago are written")
    args = parser.parse_args(argv)
    if not args.data.is_dir():
        print(f"error: {args.data}: no such directory (set --data)", file=sys.stderr)
        return 1
    facts = build_robots(args.data, args.robots)
    for name, log in (("tx40", load_tx40(args.data / "tx40")),
                      ("tiago", load_tiago(args.data / "tiago"))):
        save_log(log, args.outdir / f"{name}.h5")
        tau = log.streams["tau"]
        rms = np.sqrt((tau.data**2).mean(axis=0))
        print(f"{name}: {log.n_samples} samples at {log.rate_hz:g} Hz, "
              f"t = {log.time[0]:.2f}..{log.time[-1]:.2f} s; tau rms "
              + ", ".join(f"{n}={r:.3g}" for n, r in zip(tau.names, rms, strict=True)))
    for k, v in facts.items():
        print(f"{k}: {v}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
