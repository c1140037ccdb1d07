"""SGP scaling: fit time, peak memory and held-out accuracy vs the number of samples N.

    .venv/bin/python bench/bench_sgp_scale.py [--quick]

Data: the bundled 3-link arm (thesis §3.4.4) from ``diegocal.sim.dynamics`` (excitation
trajectory, rigid body + viscous + Coulomb friction + position-dependent friction near joint 3's
limit, 0.01 N·m noise); training = the first N samples of one log, test = 1000 samples of a log
with another seed. Rows, all timed in the same run with one BLAS thread:

- ``sgp exact``: SGPOptions(kind="sgp", inference="exact"): hyperparameters by ML-II on at most
  ``hyper_max`` = 1000 samples, exact posterior on all N (shared W, n Cholesky factors of N×N);
- ``sgp sparse``: the same with inference="sparse" (DTC/VFE, 300 k-means inducing inputs);
- ``gp exact``: our zero-mean GP (kind="gp"), the same kernel as the reference;
- ``sklearn gpr``: the reference, scikit-learn's GaussianProcessRegressor per joint with
  ConstantKernel × RBF(ARD, 9 length-scales) + WhiteKernel, zero mean (normalize_y=False, the
  same model as ``gp exact``), ML-II on all N
  (skipped above 2000 samples: O(N³) per optimiser step).

``auto`` inference switches exact → sparse above SGPOptions.exact_max = 3000 samples per joint.
Peak memory is tracemalloc's peak of Python/numpy allocations during the fit; times are taken
with tracemalloc on for every method alike.
"""

from __future__ import annotations

import sys
import time
import tracemalloc

import numpy as np

from diegocal.robot import BUNDLED_ROBOTS, load_robot
from diegocal.sgp import SGPOptions, fit_dynamics, nmse
from diegocal.sim.dynamics import DynamicsOptions, simulate_dynamics
from diegocal.sim.effects import parse_effects

SKLEARN_MAX = 2000


def simulate(robot, duration: float, seed: int):
    opts = DynamicsOptions(
        duration=duration,
        rate_hz=50.0,
        trajectory="excitation",
        effects=parse_effects(["position_friction:joint3"]),
        noise=0.01,
    )
    return simulate_dynamics(robot, opts, np.random.default_rng(seed)).without_truth()


def arrays(log, robot, n=None):
    return tuple(
        log.stream(s).select(robot.joint_names).data[:n] for s in ("q", "qd", "qdd", "tau")
    )


def measure(fit):
    """(seconds, peak MiB, result) of one call."""
    tracemalloc.start()
    start = time.perf_counter()
    out = fit()
    seconds = time.perf_counter() - start
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return seconds, peak / 2**20, out


def row(N, name, sec, mib, err) -> None:
    print(
        f"{N:5d}  {name:12s} {sec:8.2f} {mib:9.1f}  {np.array2string(err, precision=4)}", flush=True
    )


def sklearn_fit_predict(U, Y, Uq, seed):
    import warnings

    from sklearn.exceptions import ConvergenceWarning
    from sklearn.gaussian_process import GaussianProcessRegressor
    from sklearn.gaussian_process.kernels import RBF, WhiteKernel
    from sklearn.gaussian_process.kernels import ConstantKernel as C

    warnings.filterwarnings("ignore", category=ConvergenceWarning)
    preds = []
    for j in range(Y.shape[1]):
        kernel = C(1.0) * RBF(np.ones(U.shape[1]), (1e-2, 1e3)) + WhiteKernel(1e-2, (1e-8, 1e1))
        gpr = GaussianProcessRegressor(kernel, normalize_y=False, random_state=seed)
        gpr.fit(U, Y[:, j])
        preds.append(gpr)
    return lambda Uq_: np.column_stack([g.predict(Uq_) for g in preds])


def main(quick: bool) -> None:
    from threadpoolctl import threadpool_limits

    robot = load_robot(BUNDLED_ROBOTS / "arm3")
    sizes = [250, 500, 1000] if quick else [250, 500, 1000, 2000, 4000]
    train = simulate(robot, duration=max(sizes) / 50.0 + 0.1, seed=1)
    test = simulate(robot, duration=20.1, seed=2)
    qt, qdt, qddt, taut = arrays(test, robot, 1000)
    Ut = np.hstack([qt, qdt, qddt])
    print(
        f"arm3, {robot.n_joints} joints; test: 1000 held-out samples (another seed); "
        "one BLAS thread; nMSE per joint on the held-out torques"
    )
    header = f"{'N':>5}  {'method':12s} {'fit s':>8} {'peak MiB':>9}  held-out nMSE per joint"
    print(header)
    print("-" * len(header))
    rows = {}
    with threadpool_limits(1):
        for N in sizes:
            q, qd, qdd, tau = arrays(train, robot, N)
            log = train.slice(0, N)
            for name, opts in (
                ("sgp exact", SGPOptions(kind="sgp", inference="exact")),
                ("sgp sparse", SGPOptions(kind="sgp", inference="sparse")),
                ("gp exact", SGPOptions(kind="gp", inference="exact")),
            ):
                sec, mib, model = measure(lambda o=opts, lg=log: fit_dynamics(lg, robot, o))
                err = nmse(model.predict_arrays(qt, qdt, qddt).tau, taut)
                rows[(N, name)] = err
                row(N, name, sec, mib, err)
            if N <= SKLEARN_MAX:
                U = np.hstack([q, qd, qdd])
                sec, mib, predict = measure(lambda U=U, tau=tau: sklearn_fit_predict(U, tau, Ut, 0))
                err = nmse(predict(Ut), taut)
                row(N, "sklearn gpr", sec, mib, err)
            else:
                print(f"{N:5d}  {'sklearn gpr':12s} {'skipped (N > ' + str(SKLEARN_MAX) + ')':>19}")
    print()
    print("accuracy loss of sparse vs exact SGP on the same data (held-out nMSE ratio, per joint):")
    for N in sizes:
        ratio = rows[(N, "sgp sparse")] / np.maximum(rows[(N, "sgp exact")], 1e-12)
        print(f"  N={N:5d}: {np.array2string(ratio, precision=3)}")


if __name__ == "__main__":
    main(quick="--quick" in sys.argv[1:])
