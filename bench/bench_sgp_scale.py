"""SGP scaling: fit time, peak memory and held-out accuracy against N; the cost of one likelihood
evaluation; the accuracy sparse inference gives up against exact inference on the same data.

    .venv/bin/python bench/bench_sgp_scale.py [--quick]

Data: the bundled 3-link arm (thesis §3.4.4) from ``diegocal.sim.dynamics`` (excitation
trajectory, rigid body + viscous + Coulomb friction + position-dependent friction near joint 3's
limit, 0.01 N·m noise); training = the first N samples of one log, test = 1000 samples of a log
with another seed. Everything runs in one process with one BLAS thread (threadpoolctl), so CPU
time (``time.process_time``) is the figure to compare; wall time is printed next to it (the
machine is shared) with the load average before and after.

Table 1, fits (n = 3 joints fitted jointly by ours, one at a time by scikit-learn):

- ``sgp exact``: SGPOptions(kind="sgp", inference="exact"), the defaults: the guard (GP on
  q, qd; per joint a blocked 5-fold cross-validation between the learnt, released and
  parametric-only hyperparameters), hyperparameters by ML-II on at most ``hyper_max`` =
  1000 samples, exact posterior on all N (shared W, n Cholesky factors of N×N);
- ``sgp exact all``: the same with hyper_max = N: ML-II on all N samples (N ≤ 2000);
- ``sgp sparse``: inference="sparse": hyperparameters as the estimator learns them for sparse
  inference (at this commit: exact ML-II on the ≤ hyper_max subsample, as ``sgp exact``), then
  the DTC/VFE posterior with 300 k-means inducing inputs on all N, O(N M²);
- ``sgp-ng exact``: the SGP without the guard (GP on q, qd, qdd, ML-II from two starts on at most
  1000 samples), whose GP part is never switched off, so the sparse approximation has work to do;
- ``sgp-ng sparse=``: the sparse posterior (300 k-means inducing inputs) with the hyperparameters
  of ``sgp-ng exact``: the loss of the inducing-point approximation alone, same data, same
  hyperparameters (its time is the posterior's only);
- ``gp exact 1st``: our zero-mean GP (kind="gp") with one start (restarts=0) and hyper_max = N:
  the model, data and number of starts of the reference below;
- ``sklearn gpr``: scikit-learn's GaussianProcessRegressor per joint with ConstantKernel ×
  RBF(ARD, 9 length-scales) + WhiteKernel, zero mean (normalize_y=False), ML-II on all N, one
  start (N ≤ 2000).

Table 2: CPU ms of one negative log likelihood + gradient evaluation at fixed hyperparameters
(the cost depends on the shapes only): ours for 3 outputs jointly (``gp``: the model sklearn fits;
``sgp``: with the regressor's m base parameters as shared W; ``vfe``: the sparse bound with 300
inducing inputs) against scikit-learn's ``log_marginal_likelihood(eval_gradient=True)`` for one.

Peak memory is tracemalloc's peak of Python/numpy allocations during the call (LAPACK's small
workspaces are not counted); tracemalloc is on for every method alike. ``auto`` inference switches
exact → sparse above SGPOptions.exact_max = 3000 samples per joint.
"""

from __future__ import annotations

import os
import sys
import time
import tracemalloc
from dataclasses import replace

import numpy as np

from diegocal.robot import BUNDLED_ROBOTS, load_robot
from diegocal.sgp import DynamicsModel, SGPOptions, fit_dynamics, nmse
from diegocal.sgp.gp import Hyperparameters, negative_log_likelihood
from diegocal.sgp.kernels import SquaredExponential, Subspace
from diegocal.sgp.regressor import base_parameters
from diegocal.sim.dynamics import DynamicsOptions, simulate_dynamics
from diegocal.sim.effects import parse_effects

FULL = {"exact": (250, 500, 1000, 2000, 4000), "sparse": (10000, 20000), "reference": 2000}
QUICK = {"exact": (250, 500, 1000), "sparse": (4000,), "reference": 1000}
N_TEST = 1000


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
    return tuple(log.stream(s).select(robot.joint_names).data[:n] for s in ("q", "qd", "qdd", "tau"))


def measure(call):
    """(wall s, CPU s, peak MiB, result) of one call."""
    tracemalloc.start()
    wall, cpu = time.perf_counter(), time.process_time()
    out = call()
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return wall, cpu, peak / 2**20, out


def load() -> str:
    return "load average {:.2f} {:.2f} {:.2f}".format(*os.getloadavg())


def sklearn_kernel(p: int):
    from sklearn.gaussian_process.kernels import RBF, WhiteKernel
    from sklearn.gaussian_process.kernels import ConstantKernel as C

    return C(1.0) * RBF(np.ones(p), (1e-2, 1e3)) + WhiteKernel(1e-2, (1e-8, 1e1))


def sklearn_fit(U, Y, seed: int = 0):
    """One GaussianProcessRegressor per column of Y; returns predict(Uq) -> (Nq, n)."""
    import warnings

    from sklearn.exceptions import ConvergenceWarning
    from sklearn.gaussian_process import GaussianProcessRegressor

    warnings.filterwarnings("ignore", category=ConvergenceWarning)
    gprs = [
        GaussianProcessRegressor(sklearn_kernel(U.shape[1]), normalize_y=False, random_state=seed).fit(U, y)
        for y in Y.T
    ]
    return lambda Uq: np.column_stack([g.predict(Uq) for g in gprs])


# ----------------------------------------------------------------------------- table 1
def fit_rows(N: int, sizes: dict):
    """(name, options or "sklearn") for the methods run at N."""
    rows = []
    if N <= max(sizes["exact"]):
        rows.append(("sgp exact", SGPOptions(kind="sgp", inference="exact")))
    if N <= sizes["reference"] and N > SGPOptions().hyper_max:
        rows.append(("sgp exact all", SGPOptions(kind="sgp", inference="exact", hyper_max=N)))
    rows.append(("sgp sparse", SGPOptions(kind="sgp", inference="sparse")))
    if N <= max(sizes["exact"]):
        rows.append(("sgp-ng exact", SGPOptions(kind="sgp", inference="exact", guard=False)))
        rows.append(("sgp-ng sparse=", "same hyperparameters"))
    if N <= sizes["reference"]:
        rows.append(("gp exact 1st", SGPOptions(kind="gp", inference="exact", restarts=0, hyper_max=N)))
        rows.append(("sklearn gpr", "sklearn"))
    return rows


def fit_one(robot, train, N: int, opts, previous):
    """(wall s, CPU s, peak MiB, predict(q, qd, qdd) -> tau, model or None) of one row."""
    q, qd, qdd, tau = arrays(train, robot, N)
    if opts == "sklearn":
        wall, cpu, mib, predict = measure(lambda: sklearn_fit(np.hstack([q, qd, qdd]), tau))
        return wall, cpu, mib, lambda *u: predict(np.hstack(u)), None
    if opts == "same hyperparameters":  # the previous row's, with a sparse posterior
        model = DynamicsModel(robot, replace(previous.options, inference="sparse"))
        state = {"base": previous.base_.to_dict(), "hyper": previous.gp_.hyper_, "inducing": None}
        wall, cpu, mib, model = measure(lambda: model.fit_arrays(q, qd, qdd, tau, state))
    else:
        wall, cpu, mib, model = measure(lambda: fit_dynamics(train.slice(0, N), robot, opts))
    return wall, cpu, mib, lambda *u: model.predict_arrays(*u).tau, model


def fit_table(robot, train, test, sizes: dict) -> dict:
    qt, qdt, qddt, taut = arrays(test, robot, N_TEST)
    head = f"{'N':>6}  {'method':14s} {'wall s':>8} {'CPU s':>8} {'peak MiB':>9}  held-out nMSE per joint"
    print(head)
    print("-" * len(head))
    errors = {}
    for N in sorted(set(sizes["exact"]) | set(sizes["sparse"])):
        model = None
        for name, opts in fit_rows(N, sizes):
            wall, cpu, mib, predict, model = fit_one(robot, train, N, opts, model)
            err = errors[(N, name)] = nmse(predict(qt, qdt, qddt), taut)
            print(
                f"{N:6d}  {name:14s} {wall:8.1f} {cpu:8.1f} {mib:9.1f}  {np.array2string(err, precision=5)}",
                flush=True,
            )
    return errors


def sparse_loss(errors: dict) -> None:
    print("\naccuracy sparse gives up against exact on the same data (held-out nMSE per joint):")
    for exact, sparse in (("sgp exact", "sgp sparse"), ("sgp-ng exact", "sgp-ng sparse=")):
        print(f"  {sparse} vs {exact}:")
        for N in sorted({N for N, name in errors if name == exact}):
            ex, sp = errors[(N, exact)], errors[(N, sparse)]
            print(
                f"    N={N:5d}: exact {np.array2string(ex, precision=5)}  sparse {np.array2string(sp, precision=5)}"
                f"  ratio {np.array2string(sp / ex, precision=3)}"
            )


# ----------------------------------------------------------------------------- table 2
def cpu_ms(call, min_seconds: float = 1.0) -> float:
    call()  # warm-up
    n, start = 0, time.process_time()
    while True:
        call()
        n += 1
        spent = time.process_time() - start
        if spent >= min_seconds or n >= 20:
            return 1e3 * spent / n


def likelihood_table(robot, train, sizes: dict) -> None:
    from sklearn.gaussian_process import GaussianProcessRegressor

    rng = np.random.default_rng(0)
    n = robot.n_joints
    q, qd, qdd, tau = arrays(train, robot)
    U = np.hstack([q, qd, qdd])
    U = (U - U.mean(0)) / U.std(0)
    m = base_parameters(robot, SGPOptions().friction).n_base
    print(f"\none likelihood + gradient evaluation, CPU ms ({n} outputs jointly vs sklearn's one; m = {m}):")
    head = f"{'N':>6} {'ours gp':>9} {'per output':>10} {'ours sgp':>9} {'ours vfe':>9} {'sklearn':>9}"
    print(head)
    print("-" * len(head))
    gp_kernels = [SquaredExponential(U.shape[1])] * n
    sgp_kernels = [Subspace(np.arange(2 * n), SquaredExponential(2 * n))] * n
    for N in sorted(set(sizes["exact"]) | set(sizes["sparse"])):
        Un, Yn = U[:N], tau[:N]
        F = rng.standard_normal((N, n, m))

        def ours(kernels, F, inducing=None, Un=Un, Yn=Yn):
            sizes_ = [k.n_params for k in kernels]
            x = Hyperparameters(0.0, np.log(0.1 * Yn.std(0)), tuple(np.zeros(s) for s in sizes_)).pack()
            return cpu_ms(lambda: negative_log_likelihood(x, kernels, Un, Yn, F, sizes_, inducing=inducing))

        exact = N <= max(sizes["exact"])
        gp = ours(gp_kernels, F[:, :, :0]) if exact else float("nan")
        sgp = ours(sgp_kernels, F) if exact else float("nan")
        vfe = ours(sgp_kernels, F, inducing=Un[rng.choice(N, min(300, N), replace=False)])
        ref = float("nan")
        if N <= sizes["reference"]:
            gpr = GaussianProcessRegressor(sklearn_kernel(U.shape[1]), optimizer=None).fit(Un, Yn[:, 0])
            ref = cpu_ms(lambda g=gpr: g.log_marginal_likelihood(g.kernel_.theta, eval_gradient=True))
        print(f"{N:6d} {gp:9.1f} {gp / n:10.1f} {sgp:9.1f} {vfe:9.1f} {ref:9.1f}", flush=True)


def main(quick: bool) -> None:
    from threadpoolctl import threadpool_limits

    sizes = QUICK if quick else FULL
    robot = load_robot(BUNDLED_ROBOTS / "arm3")
    n_max = max(max(sizes["exact"]), max(sizes["sparse"]))
    train = simulate(robot, duration=n_max / 50.0 + 0.1, seed=1)
    test = simulate(robot, duration=N_TEST / 50.0 + 0.1, seed=2)
    print(
        f"arm3, {robot.n_joints} joints; test: {N_TEST} held-out samples (another seed); one BLAS thread; "
        f"nMSE per joint on the held-out torques; {load()}"
    )
    with threadpool_limits(1):
        errors = fit_table(robot, train, test, sizes)
        sparse_loss(errors)
        likelihood_table(robot, train, sizes)
    print(f"\n{load()}")


if __name__ == "__main__":
    main(quick="--quick" in sys.argv[1:])
