"""SGP at the sizes labs record: fit time, peak memory and held-out accuracy against N, beside
scikit-learn's GaussianProcessRegressor (and GPyTorch when it is installed) in the same run.

    python bench/bench_sgp_scale.py [--quick] [--sizes 1000,2000,5000,10000,20000] [--no-gpytorch]

Data: the bundled 3-link arm (thesis §3.4.4) from ``diegocal.sim.dynamics``: excitation
trajectory at 50 Hz, rigid body + viscous + Coulomb friction + a hidden cable-like friction near
joint 3's limit (``position_friction``), 0.01 N·m noise. Training = the first N samples of one
log (seed 1); test = 2,000 samples of another trajectory of the *same* robot (seed 2's trajectory
with seed 1's friction). nMSE per joint on the measured held-out torques.

Table 1, one row per fit (defaults a user gets unless named):

- ``pr``, ``prgp``: SGPOptions(kind=...), inference auto;
- ``sgp auto``: the default ``diegocal sgp-fit`` (exact up to SGPOptions.exact_max = 3,000
  samples, sparse above);
- ``sgp exact`` / ``sgp sparse``: the other inference where auto chose one (exact up to 10,000):
  the accuracy sparse inference gives up, same data, same seed;
- ``sklearn``: GaussianProcessRegressor per joint, ConstantKernel × RBF(9 ARD length-scales) +
  WhiteKernel, zero mean, ML-II on all N from one start (the model of our ``gp`` kind), N ≤ 2,000
  (at 2,000 it took 5 min at the last note; its cost grows as N³ per optimiser step);
- ``gpytorch``: GPyTorch's ExactGP per joint, the same kernel, 50 Adam steps (lr 0.1) on the exact
  marginal likelihood (its tutorials' recipe), torch on one thread, N ≤ 2,000 (at 4,000 it took
  273 CPU-s).

Time: wall and CPU seconds of the fit (``time.process_time``: the process's CPU, every thread);
memory: tracemalloc's peak of Python/numpy allocations during the fit (LAPACK's workspaces are not
counted; torch's allocator is not seen at all: "-" in the gpytorch rows). The machine is shared:
the load average is printed before and after; compare CPU seconds.

Table 2, the verdicts: per N and joint, SGP (auto) against PR and PRGP, paired over 10
contiguous blocks of the test log: "better"/"worse" when the nMSE difference exceeds one standard
error of the paired per-block difference and 0.1 % of the reference's nMSE, else "tied". These
judge one trajectory per size (the first N samples of one run); ``bench_sgp_sizes.py`` judges the
estimator at each size over independent runs.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
import tracemalloc
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/ is not installed
from diegocal.evaluate import block_mse, paired_se, split_blocks  # noqa: E402
from diegocal.parallel import one_blas_thread  # noqa: E402
from diegocal.robot import BUNDLED_ROBOTS, load_robot  # noqa: E402
from diegocal.sgp import SGPOptions, fit_dynamics  # noqa: E402
from diegocal.sgp.model import DEFAULT_GUARD  # noqa: E402
from experiments.sgp.common import SCALE_RATE, friction_case, same_robot  # noqa: E402

SIZES = (1000, 2000, 5000, 10000, 20000)
QUICK = (500, 1000, 4000)
EXACT_MAX, SKLEARN_MAX, GPYTORCH_MAX = 10000, 2000, 2000
RATE, N_TEST, BLOCKS = SCALE_RATE, 2000, 10


simulate = friction_case  # the benches' log (experiments.sgp.common)


def arrays(log, robot, n=None):
    return tuple(log.stream(s).select(robot.joint_names).data[:n] for s in ("q", "qd", "qdd", "tau"))


def verdict(diff: float, se: float, ref: float) -> str:
    """"better"/"worse" when a difference of nMSE exceeds one standard error and 0.1 % of the
    reference's nMSE ``ref`` (equal to rounding is tied), else "tied"."""
    se = max(se, 1e-3 * ref)
    return "better" if diff < -se else "worse" if diff > se else "tied"


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


# ----------------------------------------------------------------------------- references
def sklearn_fit(U, Y):
    """One GaussianProcessRegressor per column of Y; returns predict(Uq) -> (Nq, n)."""
    import warnings

    from sklearn.exceptions import ConvergenceWarning
    from sklearn.gaussian_process import GaussianProcessRegressor
    from sklearn.gaussian_process.kernels import RBF, WhiteKernel
    from sklearn.gaussian_process.kernels import ConstantKernel as C

    warnings.filterwarnings("ignore", category=ConvergenceWarning)
    kernel = C(1.0) * RBF(np.ones(U.shape[1]), (1e-2, 1e3)) + WhiteKernel(1e-2, (1e-8, 1e1))
    gprs = [GaussianProcessRegressor(kernel, normalize_y=False, random_state=0).fit(U, y) for y in Y.T]
    return lambda Uq: np.column_stack([g.predict(Uq) for g in gprs])


def gpytorch_fit(U, Y, steps: int = 50):
    """GPyTorch ExactGP per column of Y (scaled RBF with ARD + Gaussian noise, zero mean), Adam on
    the exact marginal likelihood; returns predict(Uq) -> (Nq, n)."""
    import gpytorch
    import torch

    torch.set_num_threads(1)

    class Exact(gpytorch.models.ExactGP):
        def __init__(self, x, y, likelihood):
            super().__init__(x, y, likelihood)
            self.mean_module = gpytorch.means.ZeroMean()
            self.covar_module = gpytorch.kernels.ScaleKernel(gpytorch.kernels.RBFKernel(ard_num_dims=x.shape[1]))

        def forward(self, x):
            return gpytorch.distributions.MultivariateNormal(self.mean_module(x), self.covar_module(x))

    x = torch.as_tensor(U, dtype=torch.float64)
    models = []
    for y in Y.T:
        yt = torch.as_tensor(y, dtype=torch.float64)
        lik = gpytorch.likelihoods.GaussianLikelihood()
        model = Exact(x, yt, lik).double()
        model.train()
        lik.train()
        opt = torch.optim.Adam(model.parameters(), lr=0.1)
        mll = gpytorch.mlls.ExactMarginalLogLikelihood(lik, model)
        for _ in range(steps):
            opt.zero_grad()
            loss = -mll(model(x), yt)
            loss.backward()
            opt.step()
        model.eval()
        lik.eval()
        models.append(model)

    def predict(Uq):
        xq = torch.as_tensor(Uq, dtype=torch.float64)
        with torch.no_grad(), gpytorch.settings.fast_pred_var():
            return np.column_stack([m(xq).mean.numpy() for m in models])

    return predict


def has_gpytorch() -> bool:
    try:
        import gpytorch  # noqa: F401
    except ImportError:
        return False
    return True


# ----------------------------------------------------------------------------- table 1
def rows_at(N: int, gpytorch: bool, no_region: bool = False, references: bool = True) -> list:
    """(label, options | "sklearn" | "gpytorch") of the fits run at N; ``no_region``: also the SGP
    without Guard.region (``sgp-fit --no-region``); without ``references`` no scikit-learn/GPyTorch."""
    auto = "exact" if N <= SGPOptions.exact_max else "sparse"
    other = "sparse" if auto == "exact" else "exact"
    rows = [("pr", SGPOptions(kind="pr")), ("prgp", SGPOptions(kind="prgp")), (f"sgp auto ({auto})", SGPOptions())]
    if N >= 2000 and (other == "sparse" or N <= EXACT_MAX):
        rows.append((f"sgp {other}", SGPOptions(inference=other)))
    if no_region:
        no_cut = replace(DEFAULT_GUARD, region=False, joint_region=False)  # as sgp-fit --no-region
        rows.append(("sgp no region", SGPOptions(guard_options=no_cut)))
    if references and N <= SKLEARN_MAX:
        rows.append(("sklearn", "sklearn"))
    if references and gpytorch and N <= GPYTORCH_MAX:
        rows.append(("gpytorch", "gpytorch"))
    return rows


def fit_one(robot, train, N: int, opts):
    """(wall s, CPU s, peak MiB, predict(q, qd, qdd) -> tau) of one row."""
    q, qd, qdd, tau = arrays(train, robot, N)
    if isinstance(opts, str):
        fit = sklearn_fit if opts == "sklearn" else gpytorch_fit
        U = np.hstack([q, qd, qdd])
        mu, sd = U.mean(0), U.std(0)  # both references get standardised inputs
        wall, cpu, mib, predict = measure(lambda: fit((U - mu) / sd, tau))
        return wall, cpu, mib, lambda *u: predict((np.hstack(u) - mu) / sd)
    wall, cpu, mib, model = measure(lambda: fit_dynamics(train.slice(0, N), robot, opts))
    return wall, cpu, mib, lambda *u: model.predict_arrays(*u).tau


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help=f"sizes {QUICK}")
    ap.add_argument("--sizes", default=None, help="comma list of training sizes")
    ap.add_argument("--no-gpytorch", action="store_true")
    ap.add_argument("--no-region", action="store_true", help="add the SGP with sgp-fit --no-region")
    ap.add_argument("--no-references", action="store_true", help="no scikit-learn or GPyTorch rows")
    args = ap.parse_args(argv)
    sizes = QUICK if args.quick else SIZES
    if args.sizes:
        try:
            sizes = tuple(int(s) for s in args.sizes.split(","))
        except ValueError:
            sys.exit(f"bench_sgp_scale: --sizes expects integers separated by commas, got {args.sizes!r}")
    gpytorch = has_gpytorch() and not args.no_gpytorch
    sys.stdout.reconfigure(line_buffering=True)
    head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    robot = load_robot(BUNDLED_ROBOTS / "arm3")
    train = simulate(robot, max(sizes), seed=1)
    test = simulate(robot, N_TEST, seed=2, friction=same_robot(train, robot))
    qt, qdt, qddt, taut = arrays(test, robot, N_TEST)
    labels = split_blocks(N_TEST, BLOCKS).labels()
    print(f"diegocal commit {head or 'unknown'}; python bench/bench_sgp_scale.py {' '.join(argv or sys.argv[1:])}")
    print(f"arm3 with a hidden friction on joint3; test: {N_TEST} samples of the same robot; {load()}")
    print(f"gpytorch: {'on' if gpytorch else 'not installed or --no-gpytorch'}\n")
    line = f"{'N':>6}  {'method':18s} {'wall s':>8} {'CPU s':>8} {'peak MiB':>9}  held-out nMSE per joint"
    print(line + "\n" + "-" * len(line))
    blocks = {}
    for N in sizes:
        for label, opts in rows_at(N, gpytorch, args.no_region, not args.no_references):
            wall, cpu, mib, predict = fit_one(robot, train, N, opts)
            sq = (predict(qt, qdt, qddt) - taut) ** 2 / taut.var(axis=0)
            blocks[(N, label.split(" (")[0])] = block_mse(sq, labels)
            err = np.array2string(sq.mean(axis=0), precision=5)
            mem = "-" if label == "gpytorch" else f"{mib:.1f}"
            print(f"{N:6d}  {label:18s} {wall:8.1f} {cpu:8.1f} {mem:>9}  {err}")
    for sgp in ("sgp auto", "sgp no region") if args.no_region else ("sgp auto",):
        print(f"\n{load()}\n\n{sgp} against PR and PRGP, per joint: nMSE difference ± one SE over {BLOCKS} blocks")
        for N in sizes:
            cells = []
            for ref in ("pr", "prgp"):
                diff, se = paired_se(blocks[(N, sgp)], blocks[(N, ref)])
                se = np.maximum(se, 1e-3 * blocks[(N, ref)].mean(axis=0))  # as verdict() floors it
                for j, (d, s) in enumerate(zip(diff, se, strict=True)):
                    cells.append(f"vs {ref} j{j + 1} {verdict(d, s, 0.0)} ({d:+.2g} ± {s:.2g})")
            print(f"{N:6d}  " + "; ".join(cells))
    return 0


if __name__ == "__main__":
    with one_blas_thread():
        sys.exit(main())
