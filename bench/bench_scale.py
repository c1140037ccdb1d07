"""Long sessions (issue #33): time and peak memory of each domain's long-running command against
the log's length, with the slope per minute of log, beside a reference version in the same run.

    .venv/bin/python bench/bench_scale.py [--quick] [--minutes 1,2,5,10] [--domains stac,dynamics]
        [--ref GITREF] [--logs DIR] [--timeout S] [--mem-limit MB]

Per domain and length, one log is simulated (``diegocal simulate ...``, with this checkout's code,
so every version reads the same file) and one command runs on it in a fresh interpreter
(``python -m diegocal``, with ``PYTHONPATH`` naming the code under test):

- ``kinematics``: ``diagnose LOG --domain kinematics --jobs 2`` on diego with a hidden
  ``sensor_nonlinearity`` (the issue's log: seed 4), 100 Hz;
- ``dynamics``: ``diagnose LOG --domain dynamics`` on the Panda of example-robot-data, 1 kHz,
  7 joints, a hidden ``position_friction``;
- ``pneumatics``: ``pneumatic-fit LOG --all --jobs 2`` on diego's 76 chambers;
- ``stac``: ``stac LOG`` (one job) on diego, 100 Hz (6,000 frames per minute).

Each row: wall and CPU seconds (user + system of the command and every process it waited for,
``os.wait4``), the largest process's peak resident memory (``ru_maxrss``) and the peak of the
resident memory summed over the command's process tree (sampled every 0.2 s from /proc: what
``--jobs 2`` really holds), the 1-minute load average when the run started (the machine may be
shared: compare CPU seconds), and, for the reference rows, whether the output file agrees with
this checkout's (every number within a relative 1e-6 and every word equal, the header aside).
Under each table, the slope of a least-squares line through the rows of each version (s, CPU-s
and MB per minute of log) and the issue's goal.

``--ref GITREF`` checks GITREF out in a temporary ``git worktree`` and runs the same commands
with its code (same interpreter and packages). ``--logs DIR`` keeps the simulated logs there and
reuses them in later runs. A run over ``--timeout`` seconds (default 1800) or ``--mem-limit`` MB
(summed over its processes; default 8192, four times the goal) is stopped and shown as such, so
that ``make bench`` cannot exhaust the machine on the lengths today's code does not reach.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import sysconfig
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))  # the benches' shared table printer
from bench_stac_compare import print_table  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
PANDA = (
    Path(sysconfig.get_paths()["purelib"])
    / "cmeel.prefix/share/example-robot-data/robots/panda_description/urdf/panda.urdf"
)
MINUTES, QUICK = (1.0, 2.0, 5.0, 10.0), (0.25, 0.5)
HEADER_KEYS = {"command", "created", "version", "log", "robot", "seconds"}  # provenance and timings
REL_TOL = 1e-6
#: the table's columns: minutes, samples, version, wall s, CPU s, max RSS MB, tree MB, load, agreement
FORMATS = ("{}", "{}", "{}", "{:.1f}", "{:.1f}", "{:.0f}", "{:.0f}", "{:.2f}", "{}")


@dataclass(frozen=True)
class Domain:
    """How one domain's log is simulated and which command the bench times on it."""

    simulate: tuple[str, ...]  # the simulate command's arguments, less --duration and -o
    command: tuple[str, ...]  # the timed command's arguments after LOG, less -o
    output: str  # suffix of the command's output file
    goal: str  # the goal, as printed under the table
    rate: float  # samples per second of log (the table's frames column)


DOMAINS = {
    "kinematics": Domain(
        ("kinematics", "--robot", "diego", "--seed", "4", "--effect", "sensor_nonlinearity"),
        ("diagnose", "--domain", "kinematics", "--jobs", "2"),
        ".diagnosis.yaml",
        "10 min of log: <= 600 s wall (--jobs 2), <= 2048 MB, memory flat beyond the first minute",
        100.0,
    ),
    "dynamics": Domain(
        ("dynamics", "--robot", str(PANDA), "--rate", "1000", "--seed", "1", "--effect", "position_friction"),
        ("diagnose", "--domain", "dynamics"),
        ".diagnosis.yaml",
        "10 min of log at 1 kHz: <= 300 s wall, <= 2048 MB",
        1000.0,
    ),
    "pneumatics": Domain(
        ("pneumatics", "--robot", "diego", "--seed", "1"),
        ("pneumatic-fit", "--all", "--jobs", "2"),
        ".pneumatic.yaml",
        "76 chambers, 10 min of log: <= 600 s wall (--jobs 2), <= 2048 MB",
        100.0,
    ),
    "stac": Domain(
        ("kinematics", "--robot", "diego", "--seed", "4"),
        ("stac",),
        ".calib.yaml",
        "25,000 frames (4.2 min): <= 10 s wall, one job; 100,000 frames (16.7 min): <= 60 s, <= 2048 MB",
        100.0,
    ),
}


@dataclass(frozen=True)
class Run:
    """One timed command: wall and CPU seconds, peak memory (MB) of the largest process and of
    the whole process tree, load average at start, and why it stopped early (or "")."""

    wall: float
    cpu: float
    rss_mb: float
    tree_mb: float
    load: float
    stopped: str = ""


def diegocal(code: Path) -> tuple[list[str], dict]:
    """The command line and environment that run diegocal from the source tree ``code`` (``-P``: the
    working directory is not put before ``PYTHONPATH``, so a run from this checkout's root still
    imports ``code``'s diegocal)."""
    env = {**os.environ, "PYTHONPATH": str(code), "COLUMNS": "100"}
    return [sys.executable, "-P", "-m", "diegocal"], env


def tree_rss(pid: int) -> dict[int, float]:
    """Resident memory (MB) of ``pid`` and of every descendant, by process id, read from /proc."""
    children: dict[int, list[int]] = {}
    rss: dict[int, int] = {}
    for entry in os.scandir("/proc"):
        if not entry.name.isdigit():
            continue
        try:
            with open(f"/proc/{entry.name}/stat") as f:
                stat = f.read()
            with open(f"/proc/{entry.name}/statm") as f:
                pages = int(f.read().split()[1])
        except (OSError, ValueError, IndexError):
            continue
        p = int(entry.name)
        children.setdefault(int(stat.rsplit(")", 1)[1].split()[1]), []).append(p)
        rss[p] = pages
    found, todo = {}, [pid]
    while todo:
        p = todo.pop()
        found[p] = rss.get(p, 0) * os.sysconf("SC_PAGE_SIZE") / 2**20
        todo.extend(children.get(p, ()))
    return found


def tree_rss_mb(pid: int) -> float:
    """Resident memory (MB) of ``pid`` and every descendant together (0 once it is gone)."""
    return sum(tree_rss(pid).values())


def timed(cmd: list[str], env: dict, timeout: float | None, mem_limit: float | None) -> Run:
    """Run ``cmd``, sampling its process tree's memory; stop it past ``timeout`` s or ``mem_limit`` MB."""
    load = os.getloadavg()[0]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True)
    peak, stopped, done = [0.0], [""], threading.Event()

    def sample() -> None:
        while not done.wait(0.2):
            peak[0] = max(peak[0], tree_rss_mb(proc.pid))
            over_time = timeout is not None and time.perf_counter() - t0 > timeout
            if over_time or (mem_limit is not None and peak[0] > mem_limit):
                stopped[0] = f"stopped: over {timeout:.0f} s" if over_time else f"stopped: over {mem_limit:.0f} MB"
                os.killpg(proc.pid, 9)
                return

    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    err = proc.stderr.read()
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    wall = time.perf_counter() - t0
    done.set()
    sampler.join()
    if proc.returncode != 0 and not stopped[0]:
        raise RuntimeError(f"{' '.join(cmd[2:])} exited {proc.returncode}: {err.decode()[-2000:]}")
    return Run(wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024, peak[0], load, stopped[0])


def simulate(name: str, minutes: float, logs: Path) -> Path:
    """The domain's log of ``minutes`` minutes in ``logs`` (simulated unless it is there)."""
    path = logs / f"{name}_{minutes:g}min.h5"
    if not path.exists():
        cli, env = diegocal(ROOT)
        args = [*DOMAINS[name].simulate, "--duration", f"{60 * minutes:g}", "-o", str(path), "-q"]
        subprocess.run([*cli, "simulate", *args], env=env, check=True, stdout=subprocess.DEVNULL)
    return path


def leaves(node, path=()):
    """(path, value) of every scalar in a YAML document, header fields aside."""
    if isinstance(node, dict):
        for k, v in node.items():
            if k not in HEADER_KEYS:
                yield from leaves(v, (*path, str(k)))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from leaves(v, (*path, str(i)))
    else:
        yield path, node


def agreement(ours: Path, theirs: Path) -> str:
    """Whether two output files agree: "same" when every number is within REL_TOL and every word
    is equal; else the first difference (a path in the file) or the largest relative difference."""
    a, b = (dict(leaves(yaml.safe_load(p.read_text()))) for p in (ours, theirs))
    if a.keys() != b.keys():
        return f"differs: {'/'.join(sorted(a.keys() ^ b.keys(), key=len)[0])}"
    worst, where = 0.0, ""
    for k, x in a.items():
        y = b[k]
        if isinstance(x, (int, float)) and isinstance(y, (int, float)) and not isinstance(x, bool):
            rel = abs(x - y) / max(abs(x), abs(y), 1e-12)
            if rel > worst:
                worst, where = rel, "/".join(k)
        elif x != y:
            return f"differs: {'/'.join(k)}"
    return "same" if worst <= REL_TOL else f"rel {worst:.1e} at {where}"


def slope(minutes: list[float], values: list[float]) -> float:
    """Least-squares slope of ``values`` against ``minutes`` (two lengths at least)."""
    return float(np.polyfit(minutes, values, 1)[0])


def bench_domain(name: str, lengths, versions: dict[str, Path], logs: Path, out: Path, args) -> None:
    """Time the domain's command at every length with every version; print the table and slopes."""
    dom = DOMAINS[name]
    rows, runs = [], {v: [] for v in versions}
    for minutes in lengths:
        log = simulate(name, minutes, logs)
        outputs = {}
        for i, (version, code) in enumerate(versions.items()):
            cli, env = diegocal(code)
            (out / str(i)).mkdir(exist_ok=True)  # one folder per version: files that name others agree
            outputs[version] = out / str(i) / f"{name}_{minutes:g}min{dom.output}"
            cmd = [*cli, dom.command[0], str(log), *dom.command[1:], "-o", str(outputs[version]), "-q"]
            run = timed(cmd, env, args.timeout, args.mem_limit)
            runs[version].append((minutes, run))
            same = (
                ""
                if version == "this" or run.stopped or runs["this"][-1][1].stopped
                else agreement(outputs["this"], outputs[version])
            )
            rows.append(
                (
                    f"{minutes:g}",
                    f"{minutes * 60 * dom.rate:,.0f}",
                    version,
                    run.wall,
                    run.cpu,
                    run.rss_mb,
                    run.tree_mb,
                    run.load,
                    run.stopped or same,
                )
            )
            cells = "  ".join(f.format(v) for f, v in zip(FORMATS, rows[-1], strict=True))
            print(f"  ... {name}: {cells}", file=sys.stderr, flush=True)
    print(f"\n## {name}: {' '.join(dom.command)}")
    header = ("min", "samples", "version", "wall s", "CPU s", "max RSS MB", "tree MB", "load", "output vs this")
    print_table(header, rows, FORMATS)
    for version, done in runs.items():
        kept = [(m, r) for m, r in done if not r.stopped]
        m = [m for m, _ in kept]
        if len(set(m)) < 2:
            continue
        print(
            f"  slope ({version}): {slope(m, [r.wall for _, r in kept]):.1f} s, "
            f"{slope(m, [r.cpu for _, r in kept]):.1f} CPU-s, "
            f"{slope(m, [r.tree_mb for _, r in kept]):.0f} MB per minute of log"
        )
    print(f"  goal: {dom.goal}", flush=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", default=None, help="Comma-separated log lengths in minutes (default 1,2,5,10).")
    ap.add_argument("--quick", action="store_true", help=f"Short logs only: {', '.join(map(str, QUICK))} min.")
    ap.add_argument("--domains", default=",".join(DOMAINS), help="Comma-separated: " + ", ".join(DOMAINS) + ".")
    ap.add_argument("--ref", default=None, help="Also run the code of this git ref (a temporary worktree).")
    ap.add_argument("--logs", type=Path, default=None, help="Keep the simulated logs here and reuse them.")
    ap.add_argument("--timeout", type=float, default=1800.0, help="Stop a run after this many seconds.")
    ap.add_argument(
        "--mem-limit", type=float, default=8192.0, help="Stop a run whose processes hold more MB (4 x the goal)."
    )
    args = ap.parse_args(argv)
    lengths = [float(m) for m in args.minutes.split(",")] if args.minutes else QUICK if args.quick else MINUTES
    names = [d.strip() for d in args.domains.split(",")]
    unknown = sorted(set(names) - DOMAINS.keys())
    if unknown:
        ap.error(f"unknown domain {', '.join(unknown)}; expected some of {', '.join(DOMAINS)}")
    with tempfile.TemporaryDirectory(prefix="bench_scale_") as tmp:
        tmp = Path(tmp)
        logs = args.logs or tmp
        logs.mkdir(parents=True, exist_ok=True)
        versions = {"this": ROOT}
        if args.ref:
            sha = subprocess.run(
                ["git", "-C", str(ROOT), "rev-parse", "--short", args.ref], capture_output=True, text=True, check=True
            ).stdout.strip()
            subprocess.run(
                ["git", "-C", str(ROOT), "worktree", "add", "--detach", "-q", str(tmp / "ref"), sha], check=True
            )
            versions[f"ref {sha}"] = tmp / "ref"
        head = subprocess.run(
            ["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True, text=True, check=False
        ).stdout.strip()
        print(f"this = the working tree at {head or '?'}; {os.cpu_count()} CPUs; log lengths {lengths} min")
        try:
            for name in names:
                bench_domain(name, lengths, versions, logs, tmp, args)
        finally:
            if args.ref:
                subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tmp / "ref")], check=False)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
