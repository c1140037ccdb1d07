"""Real-robot logs checked against rigid-body dynamics (TX40, TIAGo).

    .venv/bin/python bench/bench_real.py [RAW_DIR]

The logs are sample_data/real/{tx40,tiago}.h5 (made by ``diegocal import`` with the maps beside
them). For each robot: per joint the correlation of the measured torque with
``pinocchio.rnea(q, qd, qdd)`` alone and with a friction model — for the TX40 the published
priors of shared/data/real/README.md (rotor inertia, viscous, Coulomb, offsets, wrist-coupling
motor terms; nothing fitted), for TIAGo a per-joint least-squares fit of
[rnea, qd, tanh(qd/0.01), 1] (in-sample; a sanity check of signs and gains, not an
identification). Last, the TX40 torque RMSE with the priors for several derivative cut-offs:
this re-imports the raw 5 kHz recording (RAW_DIR, default ../shared/data/real; skipped without it)
with tx40.map.yaml's filter cut-off replaced, and times the import.
"""

from __future__ import annotations

import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pinocchio as pin

from diegocal.io import load_log
from diegocal.io.importers import import_log, load_map
from diegocal.robot import BUNDLED_ROBOTS, load_robot

REPO = Path(__file__).resolve().parents[1]
SAMPLE = REPO / "sample_data" / "real"
TX40_RAW = ("pos_read_data.csv", "curr_data.csv")
TX40_PRIORS = dict(
    fv=np.array([8.05, 5.53, 1.97, 1.11, 1.86, 0.65]),
    fs=np.array([7.14, 8.26, 6.34, 2.48, 3.03, 0.282]),
    ia=np.array([0.362, 0.362, 0.0988, 0.0313, 0.0468, 0.0105]),
    off=np.array([0.392, 1.37, 0.326, -0.102, -0.0288, 0.127]),
)


def rnea(robot, log):
    idx = [log.streams["q"].names.index(j) for j in robot.joint_names]
    q, qd, qdd = (log.streams[k].data[:, idx] for k in ("q", "qd", "qdd"))
    tau = np.array([pin.rnea(robot.model, robot.data, a, b, c)
                    for a, b, c in zip(q, qd, qdd, strict=True)])
    return qd, qdd, tau


def tx40_model(rb, qd, qdd):
    p = TX40_PRIORS
    model = rb + p["ia"] * qdd + p["fv"] * qd + p["fs"] * np.sign(qd) + p["off"]
    v6, a6 = qd[:, 4] + qd[:, 5], qdd[:, 4] + qdd[:, 5]
    coupling = 0.00964 * a6 + 0.616 * v6 + 1.95 * np.sign(v6)
    model[:, 4] += coupling
    model[:, 5] += coupling
    return model


def corr(a, b) -> float:
    return float(np.corrcoef(a, b)[0, 1])


def main(raw: Path) -> None:
    robot = load_robot(BUNDLED_ROBOTS / "tx40")
    log = load_log(SAMPLE / "tx40.h5")
    print(f"TX40: {SAMPLE / 'tx40.h5'}: {log.n_samples} samples at "
          f"{log.rate_hz:g} Hz, t = {log.time[0]:.2f}..{log.time[-1]:.2f} s")
    qd, qdd, rb = rnea(robot, log)
    meas = log.streams["tau"].select(robot.joint_names).data
    model = tx40_model(rb, qd, qdd)
    print(f"{'joint':<18}{'rms tau':>9}{'rms rnea':>9}{'corr rnea':>10}{'corr +priors':>13}"
          f"{'rmse +priors':>13}")
    for j, name in enumerate(robot.joint_names):
        rms_m, rms_r = np.sqrt((meas[:, j] ** 2).mean()), np.sqrt((rb[:, j] ** 2).mean())
        print(f"{name:<18}{rms_m:9.2f}{rms_r:9.2f}"
              f"{corr(meas[:, j], rb[:, j]):10.3f}{corr(meas[:, j], model[:, j]):13.3f}"
              f"{np.sqrt(((meas[:, j] - model[:, j])**2).mean()):13.2f}")
    rmse = np.sqrt(((meas - model) ** 2).mean())
    print(f"all joints: torque RMSE with the published priors {rmse:.2f}"
          " N·m (README: FIGAROH in-sample fit 2.84 with coupling, 3.36 without)")
    if (raw / "tx40").is_dir():
        print(f"{'cut-off Hz':<18}{'RMSE N·m':>9}{'import s':>10}   (raw 5 kHz recording, {raw / 'tx40'})")
        mapping = load_map(SAMPLE / "tx40.map.yaml")
        for fc in (2.5, 5.0, 10.0, 20.0, 40.0):
            start = time.perf_counter()
            lg = import_log([raw / "tx40" / f for f in TX40_RAW],
                            replace(mapping, filter=replace(mapping.filter, cutoff_hz=fc))).log
            took = time.perf_counter() - start
            a, b, c = rnea(robot, lg)
            m = lg.streams["tau"].select(robot.joint_names).data
            print(f"{fc:<18g}{np.sqrt(((m - tx40_model(c, a, b))**2).mean()):9.2f}{took:10.2f}")
    else:
        print(f"cut-off sweep skipped: it re-imports the raw recording, not found at {raw / 'tx40'}")

    robot = load_robot(BUNDLED_ROBOTS / "tiago")
    log = load_log(SAMPLE / "tiago.h5")
    print(f"\nTIAGo: {SAMPLE / 'tiago.h5'}: {log.n_samples} samples "
          f"at {log.rate_hz:g} Hz, t = {log.time[0]:.2f}..{log.time[-1]:.2f} s (wrist tau dropped)")
    qd, _, rb = rnea(robot, log)
    tau = log.streams["tau"]
    print(f"{'joint':<18}{'rms tau':>9}{'rms rnea':>9}{'corr rnea':>10}{'corr +fric':>11}"
          f"{'rnea scale':>11}")
    for name in tau.names:
        k = robot.joint_index(name)
        m = tau.column(name)
        A = np.column_stack([rb[:, k], qd[:, k], np.tanh(qd[:, k] / 0.01), np.ones_like(m)])
        x, *_ = np.linalg.lstsq(A, m, rcond=None)
        print(f"{name:<18}{np.sqrt((m**2).mean()):9.2f}{np.sqrt((rb[:, k]**2).mean()):9.2f}"
              f"{corr(m, rb[:, k]):10.3f}{corr(m, A @ x):11.3f}{x[0]:11.2f}")
    torso = tau.column("torso_lift_joint")
    print(f"torso force: measured mean {torso.mean():.1f} N, rnea mean "
          f"{rb[:, robot.joint_index('torso_lift_joint')].mean():.1f} N")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else REPO.parent / "shared" / "data" / "real")
