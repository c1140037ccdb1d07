"""The benches refuse bad arguments with one line, before any work."""

import subprocess
import sys
from pathlib import Path

BENCH = Path(__file__).resolve().parents[2] / "bench" / "bench_sgp_experiments.py"


def test_an_unknown_experiment_is_one_error_line():
    r = subprocess.run([sys.executable, str(BENCH), "--only", "wheel,reaction_wheel"], capture_output=True, text=True)
    assert r.returncode != 0
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "reaction_wheel" in lines[0] and "known: pendulum, wheel, arm3" in lines[0], r.stderr
    assert "===" not in r.stdout  # no experiment ran


def test_the_coverage_bench_refuses_too_few_runs_with_one_line():
    bench = BENCH.parent / "bench_sgp_coverage.py"
    r = subprocess.run([sys.executable, str(bench), "--runs", "2"], capture_output=True, text=True)
    assert r.returncode != 0 and r.stdout == ""
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "--runs ≥ 3" in lines[0], r.stderr
