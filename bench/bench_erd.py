"""Every URDF with joints in example-robot-data through the front door (issue #15, item 1).

    .venv/bin/python bench/bench_erd.py [--duration S] [--rate HZ] [--only SUBSTRING] [--max-joints N]

For each URDF that Pinocchio parses and that has joints: ``diegocal simulate dynamics --robot
FILE.urdf`` (the URDF named as is: continuous joints become revolute, multi-DoF joints are locked;
DESIGN.md "Robot directory") and ``diegocal sgp-fit LOG --model pr`` with no ``--robot`` (the log
names its URDF), then the fitted model against the simulator's noise-free torques. A robot counts
as identified when the PR model's torque RMSE against the truth is below the injected noise level
(--noise, 0.01 N·m) while the true torque is not (a URDF without inertias has nothing to
identify): the rigid-body + friction regressor then explains every joint's torque up to what the
data cannot resolve. Prints one row per URDF (joints kept / locked, samples, in-sample
nMSE median and max, RMS of the true torque, RMSE against the truth, CPU seconds, peak memory of the process) and the
counts: loaded, simulated, fitted, identified.

In-sample nMSE is close to 1 on joints whose torque is mostly noise (fingers, wheels of a
few grams): the truth column is the one to read there.
"""

from __future__ import annotations

import argparse
import resource
import sysconfig
import tempfile
import time
from pathlib import Path

import numpy as np
import pinocchio as pin

ERD = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix" / "share" / "example-robot-data" / "robots"


def urdfs() -> list[Path]:
    """URDFs Pinocchio parses that have at least one joint, sorted by path."""
    out = []
    for path in sorted(ERD.rglob("*.urdf")):
        try:
            model = pin.buildModelFromUrdf(str(path))
        except (RuntimeError, ValueError):
            continue
        if model.njoints > 1:
            out.append(path)
    return out


def run(argv: list[str]) -> None:
    """One diegocal command in this process; a non-zero exit raises RuntimeError."""
    from diegocal.cli import app

    try:
        app([str(a) for a in argv], standalone_mode=False)
    except SystemExit as exc:  # the one-line-error group exits with the status
        if exc.code not in (0, None):
            raise RuntimeError(f"exit {exc.code}") from None


def one(urdf: Path, args, tmp: Path) -> dict:
    from diegocal.io import load_log, load_yaml
    from diegocal.robot import load_robot
    from diegocal.sgp import load_model

    row = {"urdf": str(urdf.relative_to(ERD)), "status": "?"}
    t0 = time.process_time()
    try:
        robot = load_robot(urdf)
    except Exception as exc:  # noqa: BLE001 - a bench reports every failure and goes on
        row["status"] = f"load: {exc}"
        return row
    row.update(kept=robot.n_joints, locked=len(robot.locked))
    if args.max_joints and robot.n_joints > args.max_joints:
        row["status"] = "skipped (--max-joints)"
        return row
    log_path, model_dir = tmp / "log.h5", tmp / "log.sgp"
    try:
        run(["simulate", "dynamics", "--robot", urdf, "-o", log_path, "--duration", args.duration,
             "--rate", args.rate, "--noise", args.noise, "-q"])
    except Exception as exc:  # noqa: BLE001
        row["status"] = f"simulate: {exc}"
        return row
    try:
        run(["sgp-fit", log_path, "--model", "pr", "-o", model_dir, "-q"])
    except Exception as exc:  # noqa: BLE001
        row["status"] = f"sgp-fit: {exc}"
        return row
    log = load_log(log_path)
    model = load_model(model_dir)
    truth = log.truth.signals["tau"].select(model.joint_names).data
    rmse = float(np.sqrt(np.mean((model.predict(log.without_truth()).tau - truth) ** 2)))
    row["tau_rms"] = float(np.sqrt(np.mean(truth**2)))
    nmse = np.array(list(load_yaml(model_dir / "sgp.yaml")["nmse_in_sample"].values()))
    row.update(
        samples=log.n_samples,
        nmse_median=float(np.median(nmse)),
        nmse_max=float(nmse.max()),
        rmse=rmse,
        cpu=time.process_time() - t0,
        status=("no torque to identify" if row["tau_rms"] < args.noise else "identified")
        if rmse < args.noise
        else "fitted (RMSE above noise)",
    )
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=10.0)
    parser.add_argument("--rate", type=float, default=50.0)
    parser.add_argument("--noise", type=float, default=0.01)
    parser.add_argument("--only", default="")
    parser.add_argument("--max-joints", type=int, default=0)
    args = parser.parse_args()
    paths = [p for p in urdfs() if args.only in str(p)]
    print(f"{len(paths)} URDFs with joints in {ERD}")
    head = f"{'urdf':<62}{'kept':>5}{'lock':>5}{'T':>6}{'nMSE med':>10}{'max':>8}{'RMS τ':>9}{'RMSE':>9}"
    print(head + f"{'cpu s':>7}{'MB':>7}  status")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for path in paths:
            r = one(path, args, Path(tmp))
            rows.append(r)
            mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
            print(
                f"{r['urdf'][:61]:<62}{r.get('kept', '-'):>5}{r.get('locked', '-'):>5}{r.get('samples', '-'):>6}"
                f"{r.get('nmse_median', np.nan):>10.3g}{r.get('nmse_max', np.nan):>8.3g}"
                f"{r.get('tau_rms', np.nan):>9.3g}{r.get('rmse', np.nan):>9.2g}"
                f"{r.get('cpu', np.nan):>7.1f}{mb:>7.0f}  {r['status']}",
                flush=True,
            )
    loaded = sum("kept" in r for r in rows)
    fitted = sum("rmse" in r for r in rows)
    ident = sum(r["status"] == "identified" for r in rows)
    empty = sum(r["status"] == "no torque to identify" for r in rows)
    print(f"\n{len(rows)} URDFs: {loaded} loaded, {fitted} simulated and fitted (sgp-fit --model pr), "
          f"{ident} identified (torque RMSE against the truth < noise {args.noise} N·m), "
          f"{empty} with no torque to identify (RMS of the true torque < noise)")
    failed = [r for r in rows if r["status"] not in ("identified", "no torque to identify")
              and not r["status"].startswith("skipped")]
    for r in failed:
        print(f"  {r['urdf']}: {r['status']}")


if __name__ == "__main__":
    main()
