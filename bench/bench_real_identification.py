"""Real robots: PR vs SGP inverse-dynamics identification judged on held-out torques (thesis ch. 3).

    .venv/bin/python bench/bench_real_identification.py [--data DIR] [--tx40-stride 2]
                                                        [--tiago-stride 8] [--no-floor] [--no-region]
                                                        [--no-joint-region]

The real-robot logs of ``sample_data/real`` (Stäubli TX40, PAL TIAGo; README there: imported by
``diegocal import`` with zero-phase low-pass, derivatives, documented unit conversions), split
in time into a training and a held-out part, and on each split this script fits

- **PR**: Bayesian linear regression on the base torque regressor + viscous + Coulomb friction
  (thesis eq. 3.25, §3.3.3), ``SGPOptions(kind="pr")``;
- **SGP**: parametric part and a GP per joint jointly (thesis eq. 3.1-3.20),
  ``SGPOptions(kind="sgp")`` with the library's guard at its defaults;
- **SGP floor** (diagnostic, not a library default; ``--no-floor`` drops it): the same SGP with the
  noise floor ``SGPOptions(min_noise=0.2)``, σ_v ≥ 0.2·std(τ_j), instead of the default
  1e-4·std(τ_j) (see the note printed below the tables),

and compares them with the **nominal** rigid body (``pinocchio.rnea`` with the URDF inertias, no
friction) and, for the TX40, the nominal model plus the published friction/rotor/offset priors of
the README (``bench_real.tx40_model``: nothing fitted). Printed per split: held-out torque nMSE
per joint (MSE / variance of the held-out measurement, thesis §3.4.2), the SGP-over-PR gain
``1 − nMSE_SGP / nMSE_PR`` (> 0: SGP better), the fraction of held-out torques within ±2σ of each
fitted model, SGP's verdict against PR per joint (better / worse when the nMSE difference exceeds
one standard error of the paired difference over 10 contiguous held-out blocks, and 0.1 % of PR's
nMSE, else tied), and
the pooled RMSE (N·m) next to FIGAROH 1.0.2's reference figures from the README.

Splits: TX40 (one 7.8 s excitation at 200 Hz) half/half in time and the reverse; TIAGo rows
921-4800 for training and 4800-6791 held out (9.2-48.0 s / 48.0-67.9 s, as FIGAROH). TIAGo's
arm_5..7 efforts are unusable (exactly zero in ~90 % of samples): they are left out of the
torques (the loader leaves them out of the ``tau`` stream) — ``fit_dynamics`` then fits and
scores the torso and arm_1..4 rows only, while arm_5..7 still move and their links enter the
arm_1..4 regressor rows. The torso row is a force in N and is scored by
nMSE only; TIAGo's pooled RMSE is over arm_1..4 (N·m).

Training data are subsampled by a stride (``--tx40-stride``, ``--tiago-stride``) so that the
exact GP (N ≤ 3000) and its hyperparameter search (≤ 1000 samples) take about a minute each on
one core; the held-out part is always scored at the full rate. The library runs BLAS on one
thread. Fitting never reads anything but the training log.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pinocchio as pin

from diegocal.evaluate import block_mse, paired_se, score, split_blocks
from diegocal.io import Log, load_log, make_stream
from diegocal.robot import BUNDLED_ROBOTS, load_robot
from diegocal.sgp import SGPOptions, fit_dynamics, nmse
from diegocal.sgp.model import Guard, default_guard, log_arrays

REPO = Path(__file__).resolve().parents[1]
DEFAULT_DATA = REPO / "sample_data" / "real"
TIAGO_WINDOW = (9.2, 67.9)  # s, README rows 921-6791
TIAGO_SPLIT = 48.0  # s, README row 4800
NOISE_FLOOR = 0.2  # σ_v ≥ NOISE_FLOOR · std(τ_j) in the diagnostic "SGP floor" row
BLOCKS = 10  # contiguous held-out blocks for the SGP-vs-PR standard error
#: nMSE differences below this fraction of PR's count as tied whatever their SE (a joint where the
#: SGP fell back to PR differs from PR by rounding, 1e-10 N·m on TIAGo, with an SE of the same size)
PRACTICAL = 1e-3
#: FIGAROH 1.0.2 held-out torque RMSE (identified, nominal), N·m, shared/data/real/README.md
FIGAROH = {"tx40 half": (4.22, 4.23), "tx40 reverse": (5.18, 3.28), "tiago": (1.27, 3.87)}


# ----------------------------------------------------------------------------- data
@dataclass(frozen=True)
class Split:
    """One identification case: a training log, a held-out log and the joints scored.

    ``tau_joints``: joints with a usable torque (their rows are fitted and scored);
    ``rmse_joints``: those pooled into the RMSE (same unit, N·m).
    """

    name: str
    robot: object
    train: Log
    test: Log
    tau_joints: tuple
    rmse_joints: tuple
    stride: int


def every(log: Log, stride: int) -> Log:
    """Every ``stride``-th sample of a log (streams (T, K) -> (ceil(T/stride), K))."""
    idx = np.arange(0, log.n_samples, stride)
    streams = {k: make_stream(s.names, s.data[idx]) for k, s in log.streams.items()}
    rate = None if log.rate_hz is None else log.rate_hz / stride
    return Log(log.time[idx], streams, robot=log.robot, rate_hz=rate)


def tx40_splits(data: Path, stride: int) -> list[Split]:
    """Half/half time split of the TX40 run and its reverse (train on the second half)."""
    robot = load_robot(BUNDLED_ROBOTS / "tx40")
    log = load_log(data / "tx40.h5")
    h = log.n_samples // 2
    first, second = log.slice(0, h), log.slice(h, log.n_samples)
    joints = tuple(robot.joint_names)
    return [Split("tx40 half", robot, every(first, stride), second, joints, joints, stride),
            Split("tx40 reverse", robot, every(second, stride), first, joints, joints, stride)]


def tiago_split(data: Path, stride: int) -> Split:
    """TIAGo trained on 9.2-48.0 s, held out 48.0-67.9 s (README rows 921-4800 / 4800-6791)."""
    robot = load_robot(BUNDLED_ROBOTS / "tiago")
    log = tiago_log(data)
    k = int(np.searchsorted(log.time, TIAGO_SPLIT))
    tau_joints = log.streams["tau"].names
    arm = tuple(j for j in tau_joints if j.startswith("arm_"))
    return Split("tiago", robot, every(log.slice(0, k), stride), log.slice(k, log.n_samples),
                 tau_joints, arm, stride)


def tiago_log(data: Path) -> Log:
    """sample_data/real/tiago.h5 cut to the README's excitation, TIAGO_WINDOW (rows 921-6791)."""
    log = load_log(data / "tiago.h5")
    start, stop = np.searchsorted(log.time, TIAGO_WINDOW)
    return log.slice(int(start), int(stop))


# ----------------------------------------------------------------------------- models
def arrays(split: Split, log: Log):
    """(q, qd, qdd) of all joints and tau of the scored joints, (T, n) and (T, n_tau)."""
    q, qd, qdd = log_arrays(log, split.robot, need_tau=False)
    return q, qd, qdd, log.stream("tau").select(split.tau_joints).data


def nominal(robot, q, qd, qdd) -> np.ndarray:
    """Rigid body with the URDF inertias, no friction: ``pinocchio.rnea`` per sample, (T, n)."""
    return np.array([pin.rnea(robot.model, robot.data, a, b, c)
                     for a, b, c in zip(q, qd, qdd, strict=True)])


@dataclass(frozen=True)
class Result:
    """Held-out predictions of one method: tau (T, n_tau), its predictive std (None for the
    nominal models), fit time s, training samples, and the in-sample nMSE averaged over joints
    (≈ 0 means the model interpolates its training data)."""

    method: str
    tau: np.ndarray
    seconds: float
    n_train: int
    in_sample: float = float("nan")
    std: np.ndarray | None = None


def fit_predict(split: Split, method: str, seed: int, guard: Guard | None = None) -> Result:
    """Fit ``method`` ("pr", "sgp", "sgp floor") on the split's training part, predict held-out;
    ``guard``: the SGPs' guard options (None: the default's; ``--no-region``, ``--no-joint-region``)."""
    if method == "sgp floor":
        options = SGPOptions(kind="sgp", seed=seed, min_noise=NOISE_FLOOR, guard_options=guard)
    else:
        options = SGPOptions(kind=method, seed=seed, guard_options=guard if method == "sgp" else None)
    start = time.perf_counter()
    # TIAGo's tau stream has no wrist channel: fit_dynamics fits the joints that have a torque
    model = fit_dynamics(split.train, split.robot, options)
    assert model.joint_names == split.tau_joints
    pred = model.predict(split.test)
    return Result(method, pred.tau, time.perf_counter() - start, split.train.n_samples,
                  float(np.mean(model.nmse_in_sample_)), pred.tau_std)


def baselines(split: Split) -> list[Result]:
    """Nominal rigid body (and, for the TX40, nominal + the README's published priors)."""
    q, qd, qdd, _ = arrays(split, split.test)
    rows = [split.robot.joint_index(j) for j in split.tau_joints]
    rb = nominal(split.robot, q, qd, qdd)
    out = [Result("nominal", rb[:, rows], 0.0, 0)]
    if split.name.startswith("tx40"):
        sys.path.insert(0, str(Path(__file__).parent))
        from bench_real import tx40_model  # the priors live with the conversion bench

        out.append(Result("nominal+priors", tx40_model(rb, qd, qdd)[:, rows], 0.0, 0))
    return out


# ----------------------------------------------------------------------------- report
def rmse(split: Split, tau: np.ndarray, measured: np.ndarray) -> float:
    """Pooled RMSE over ``split.rmse_joints`` (N·m)."""
    cols = [split.tau_joints.index(j) for j in split.rmse_joints]
    return float(np.sqrt(np.mean((tau[:, cols] - measured[:, cols]) ** 2)))


def report(split: Split, results: list[Result]) -> dict:
    """Print the split's tables; return {method: (nmse per joint (n,), rmse)}."""
    measured = arrays(split, split.test)[3]
    scores = {r.method: (nmse(r.tau, measured), rmse(split, r.tau, measured)) for r in results}
    short = [j.replace("_joint", "") for j in split.tau_joints]
    print(f"\n== {split.name}: train {split.train.time[0]:.2f}-{split.train.time[-1]:.2f} s "
          f"(N = {split.train.n_samples} samples, stride {split.stride}), held out "
          f"{split.test.time[0]:.2f}-{split.test.time[-1]:.2f} s ({split.test.n_samples} samples)")
    print("held-out torque nMSE per joint (MSE / var of the held-out torque; 1 = predicting "
          "the held-out mean)")
    print(f"{'method':<16}" + "".join(f"{s:>10}" for s in short)
          + f"{'RMSE N·m':>10}{'time s':>8}{'in-sample':>11}")
    for r in results:
        e, rm = scores[r.method]
        t = f"{r.seconds:8.1f}{r.in_sample:11.2g}" if r.n_train else f"{'-':>8}{'-':>11}"
        print(f"{r.method:<16}" + "".join(f"{v:10.3f}" for v in e) + f"{rm:10.2f}" + t)
    pr = scores["pr"][0]
    for m in ("sgp", "sgp floor"):
        if m in scores:
            gain = 1.0 - scores[m][0] / np.where(pr > 0, pr, 1.0)
            print(f"{'gain ' + m:<16}" + "".join(f"{g:+10.2f}" for g in gain)
                  + f"{1.0 - scores[m][1] / scores['pr'][1]:+10.2f}")
    for r in results:
        if r.std is not None:
            cov = score(measured, r.tau, split.tau_joints, std=r.std).coverage
            print(f"{'±2σ ' + r.method:<16}" + "".join(f"{c:10.2f}" for c in cov))
    by = {r.method: r for r in results}
    labels = split_blocks(len(measured), BLOCKS).labels()
    sq = {m: (by[m].tau - measured) ** 2 / measured.var(axis=0) for m in ("pr", "sgp")}
    diff, se = paired_se(block_mse(sq["sgp"], labels), block_mse(sq["pr"], labels))
    se = np.maximum(se, PRACTICAL * sq["pr"].mean(axis=0))  # equal to rounding is tied
    words = ["worse" if d > s_ else "better" if d < -s_ else "tied" for d, s_ in zip(diff, se, strict=True)]
    print(f"{'sgp vs pr':<16}" + "".join(f"{w:>10}" for w in words)
          + f"   (nMSE difference beyond ± one SE over {BLOCKS} held-out blocks)")
    fig_id, fig_nom = FIGAROH[split.name]
    print(f"FIGAROH 1.0.2 reference (README): identified {fig_id:.2f} vs nominal {fig_nom:.2f} N·m "
          f"held-out RMSE; here PR {scores['pr'][1]:.2f}, nominal {scores['nominal'][1]:.2f}"
          + (f", nominal+priors {scores['nominal+priors'][1]:.2f}" if "nominal+priors" in scores
             else "") + " N·m" + (" (arm_1..4)" if split.name == "tiago" else ""))
    return scores


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA, help="sample_data/real")
    parser.add_argument("--tx40-stride", type=int, default=2, help="TX40 training subsampling")
    parser.add_argument("--tiago-stride", type=int, default=8, help="TIAGo training subsampling")
    parser.add_argument("--no-floor", action="store_true", help="skip the 'SGP floor' row")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--no-region", action="store_true", help="SGP without Guard.region (sgp-fit --no-region)")
    parser.add_argument(
        "--no-joint-region", action="store_true", help="SGP without Guard.joint_region (sgp-fit --no-joint-region)"
    )
    args = parser.parse_args(argv)
    guard = None
    if args.no_region or args.no_joint_region:
        region = not args.no_region
        joint_region = region and not args.no_joint_region
        guard = replace(default_guard(SGPOptions().friction), region=region, joint_region=joint_region)
    if not (args.data / "tx40.h5").exists() or not (args.data / "tiago.h5").exists():
        print(f"no real-robot data at {args.data}; skipped")
        return 0
    sys.stdout.reconfigure(line_buffering=True)  # the library runs BLAS on one thread itself
    head = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"],
                          capture_output=True, text=True).stdout.strip() or "unknown"
    print(f"diegocal commit {head}")
    cmd = "python bench/bench_real_identification.py " + " ".join(argv or sys.argv[1:])
    print(f"command: {cmd.strip()}")
    methods = ["pr", "sgp"] + ([] if args.no_floor else ["sgp floor"])
    splits = tx40_splits(args.data, args.tx40_stride) + [tiago_split(args.data,
                                                                     args.tiago_stride)]
    print("TIAGo: arm_5..7 efforts unusable (README): not fitted, not scored; torso in N.")
    for split in splits:
        results = baselines(split) + [fit_predict(split, m, args.seed, guard) for m in methods]
        report(split, results)
    if not args.no_floor:
        print(f"\nSGP floor = the SGP with σ_v ≥ {NOISE_FLOOR}·std(τ_j), SGPOptions(min_noise=...); "
              "the default floor is 1e-4·std. These torques are low-passed (not white noise): "
              "with a tiny floor ML-II can shrink σ_v until the GP interpolates the training run "
              "(in-sample nMSE ≈ 0) and extrapolates badly; compare the in-sample column.")
    return 0


if __name__ == "__main__":
    sys.exit(main())
