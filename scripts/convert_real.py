"""Build robots/tx40 and robots/tiago from the URDFs of the real recordings (shared/data/real).

    python scripts/convert_real.py [--data DIR] [--robots DIR]

tx40: ``tx40.urdf`` as is. tiago: a reduced URDF in which ``torso_lift_joint`` and
``arm_1..7_joint`` move and every other joint of ``tiago_hey5.urdf`` is fixed at its neutral value
(:func:`diegocal.io.urdf.reduce_urdf`). Each robot is built when its recording is there. The logs
are made by ``diegocal import`` with the maps in ``sample_data/real`` (``make real-data``).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import pinocchio as pin

from diegocal.io import save_yaml, write_text
from diegocal.io.urdf import reduce_urdf

REPO = Path(__file__).resolve().parents[1]
DEFAULT_DATA = Path(os.environ.get("DIEGOCAL_REAL_DATA", REPO.parent / "shared" / "data" / "real"))
TIAGO_JOINTS = ("torso_lift_joint",) + tuple(f"arm_{i}_joint" for i in range(1, 8))


def build_tx40(data: Path, robots: Path) -> str:
    tx = robots / "tx40"
    tx.mkdir(parents=True, exist_ok=True)
    write_text(tx / "robot.urdf", (data / "tx40" / "tx40.urdf").read_text())
    save_yaml({"urdf": "robot.urdf", "base_link": "base_link", "pots": [], "markers": []}, tx / "sensors.yaml")
    return f"{tx}: tx40.urdf as is"


def build_tiago(data: Path, robots: Path) -> str:
    ti = robots / "tiago"
    frozen = reduce_urdf(data / "tiago" / "tiago_hey5.urdf", ti / "robot.urdf", TIAGO_JOINTS, name="tiago")
    model = pin.buildModelFromUrdf(str(ti / "robot.urdf"))
    save_yaml({"urdf": "robot.urdf", "base_link": model.frames[1].name, "pots": [], "markers": []},
              ti / "sensors.yaml")
    mass = model.createData()
    pin.computeSubtreeMasses(model, mass)
    carried = float(mass.mass[model.getJointId("torso_lift_joint")])
    return (f"{ti}: {len(frozen)} joints fixed, moving {', '.join(model.names[1:])}; "
            f"the torso lift carries {carried:.2f} kg")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA, help="shared/data/real")
    parser.add_argument("--robots", type=Path, default=REPO / "robots", help="where tx40/ and tiago/ are written")
    args = parser.parse_args(argv)
    built = 0
    for name, build, urdf in (("tx40", build_tx40, "tx40/tx40.urdf"), ("tiago", build_tiago, "tiago/tiago_hey5.urdf")):
        if not (args.data / urdf).exists():
            print(f"{name}: no {args.data / urdf}; skipped")
            continue
        print(build(args.data, args.robots))
        built += 1
    if not built:
        print(f"error: no recordings under {args.data} (set --data)", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
