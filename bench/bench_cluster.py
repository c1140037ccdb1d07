"""Many logs beyond one machine (issue #33): ``diegocal batch`` over a folder of logs with
``--jobs 2`` (a pool of worker processes here) against ``--scheduler`` on a Dask ``LocalCluster``
of two single-threaded worker processes, on the same logs, in the same run.

    .venv/bin/python bench/bench_cluster.py [--logs-n 20] [--minutes 1] [--command stac|pneumatic-fit]
        [--folder DIR]

The logs are simulated with this checkout (``diegocal simulate``; ``--folder`` keeps and reuses
them): ``stac`` runs on diego kinematics logs (6,000 frames a minute), ``pneumatic-fit --all`` on
diego's 76 chambers. Each route's row: wall and CPU seconds of the whole batch (for the cluster, the
workers' CPU as they report it; user and system apart), the peak resident memory of each worker process (the largest and
the smallest of the two; for ``--jobs`` sampled from /proc every 0.2 s, for Dask each worker's own
``ru_maxrss``), the batch command's own peak, the load when it started, and whether every log's
output agrees with the ``--jobs`` route's (numbers within a relative 1e-6, words equal).

What a cluster of several machines needs is in the README ("On a Dask cluster"); this bench shows
that the route costs little on one machine, so the same command scales out by pointing
``--scheduler`` at a bigger cluster.
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_scale import ROOT, agreement, diegocal, tree_rss  # noqa: E402
from bench_stac_compare import print_table  # noqa: E402

#: per command: the simulate arguments (less --seed, --duration, -o), the batch's extra arguments,
#: the output files' suffix
COMMANDS = {
    "stac": (("kinematics", "--robot", "diego"), (), ".calib.yaml"),
    "pneumatic-fit": (("pneumatics", "--robot", "diego"), ("--", "--all"), ".pneumatic.yaml"),
}
#: The cluster routes, as Dask configuration: its defaults (a worker samples its tasks' stacks
#: every 10 ms for its profile), and the same without the profiler.
ROUTES = {
    "LocalCluster 2x1": {},
    "LocalCluster, no profiler": {"distributed.worker.profile.enabled": False},
}
FORMATS = ("{}", "{:.1f}", "{:.1f}", "{:.1f}", "{:.0f}", "{:.0f}", "{:.0f}", "{:.2f}", "{}")


def simulate_logs(command: str, n: int, minutes: float, folder: Path) -> None:
    """``n`` logs of ``minutes`` minutes, seeds 1..n, in ``folder`` (kept when already there)."""
    cli, env = diegocal(ROOT)
    for seed in range(1, n + 1):
        path = folder / f"log{seed:02d}.h5"
        if not path.exists():
            args = [*COMMANDS[command][0], "--seed", str(seed), "--duration", f"{60 * minutes:g}", "-o", str(path)]
            subprocess.run([*cli, "simulate", *args, "-q"], env=env, check=True, stdout=subprocess.DEVNULL)


def run_batch(cmd: list[str], env: dict) -> tuple[float, tuple, float, dict[int, float], float]:
    """Run one batch command: wall s, (user, system) CPU s of the command and its children, its own
    peak MB, each descendant's peak MB by process id, and the load when it started."""
    load, t0 = os.getloadavg()[0], time.perf_counter()
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    peaks: dict[int, float] = {}
    done = threading.Event()

    def sample() -> None:
        while not done.wait(0.2):
            for pid, mb in tree_rss(proc.pid).items():
                peaks[pid] = max(peaks.get(pid, 0.0), mb)

    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    err = proc.stderr.read()
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    done.set()
    sampler.join()
    if os.waitstatus_to_exitcode(status) != 0:
        raise RuntimeError(f"{' '.join(cmd[2:])} failed: {err.decode()[-2000:]}")
    peaks.pop(proc.pid, None)
    return wall, (usage.ru_utime, usage.ru_stime), usage.ru_maxrss / 1024, peaks, load


def worker_usage() -> tuple[float, float, float]:
    """On a Dask worker: its user and system CPU seconds and peak resident memory (MB)."""
    u = resource.getrusage(resource.RUSAGE_SELF)
    return u.ru_utime, u.ru_stime, u.ru_maxrss / 1024


def agree(folder_a: Path, folder_b: Path, suffix: str) -> str:
    """'same' when every output file of ``folder_a`` agrees with its twin in ``folder_b``."""
    files = sorted(folder_a.glob(f"*{suffix}"))
    if not files:
        return "no outputs"
    verdicts = [agreement(f, folder_b / f.name) for f in files if (folder_b / f.name).exists()]
    if len(verdicts) < len(files):
        return f"missing {len(files) - len(verdicts)} files"
    bad = [v for v in verdicts if v != "same"]
    return "same" if not bad else f"{len(bad)} differ ({bad[0]})"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--logs-n", type=int, default=20, help="How many logs (default 20).")
    ap.add_argument("--minutes", type=float, default=1.0, help="Length of each log in minutes (default 1).")
    ap.add_argument("--command", choices=sorted(COMMANDS), default="stac", help="The batch's command.")
    ap.add_argument("--folder", type=Path, default=None, help="Keep the simulated logs here and reuse them.")
    args = ap.parse_args(argv)
    import dask
    from distributed import Client, LocalCluster

    simulate_args, extra, suffix = COMMANDS[args.command]
    cli, env = diegocal(ROOT)
    with tempfile.TemporaryDirectory(prefix="bench_cluster_") as tmp:
        tmp = Path(tmp)
        logs = args.folder or tmp / "logs"
        logs.mkdir(parents=True, exist_ok=True)
        simulate_logs(args.command, args.logs_n, args.minutes, logs)
        print(f"{args.logs_n} logs of {args.minutes:g} min, `diegocal batch {args.command}`; {os.cpu_count()} CPUs")
        rows = []
        local_out = tmp / "jobs"
        local_out.mkdir()
        batch = [*cli, "batch", args.command, str(logs), "-o", str(local_out), "-q"]
        wall, cpu, own, peaks, load = run_batch([*batch, "--jobs", "2", *extra], env)
        workers = sorted(peaks.values())[-2:]
        rows.append(("--jobs 2", wall, *cpu, max(workers), min(workers), own, load, "(reference)"))
        print(f"  ... --jobs 2: {wall:.1f} s", file=sys.stderr, flush=True)

        for route, config in ROUTES.items():
            dask_out = tmp / route.replace(" ", "_")
            dask_out.mkdir()
            with (
                dask.config.set(config),
                LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster,
                Client(cluster) as client,
            ):
                before = client.run(worker_usage)
                command = [*cli, "batch", args.command, str(logs), "-o", str(dask_out), "-q"]
                wall, _, own, _, load = run_batch([*command, "--scheduler", cluster.scheduler_address, *extra], env)
                after = client.run(worker_usage)
            cpu = [sum(after[w][k] - before[w][k] for w in after) for k in (0, 1)]
            workers = [m for *_, m in after.values()]
            same = agree(local_out, dask_out, suffix)
            rows.append((route, wall, *cpu, max(workers), min(workers), own, load, same))
            print(f"  ... {route}: {wall:.1f} s", file=sys.stderr, flush=True)
        header = ("route", "wall s", "user s", "system s", "worker MB max", "worker MB min", "batch MB", "load",
                  "outputs")
        print_table(header, rows, FORMATS)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
