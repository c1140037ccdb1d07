"""The naming bench tells a missed effect the identified baseline already holds (nothing left to
name: its held-out error equals the clean twin's) from one it leaves unexplained."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench"))

import bench_diagnose  # noqa: E402


def test_an_armature_the_identified_baseline_holds_is_taken_up_not_left():
    held = bench_diagnose.run_one("dynamics", "armature", 1514417981)  # arm3 joint2: a link inertia holds it
    assert not held.named and held.taken_up
    assert abs(held.left) < 1e-3
    missed = bench_diagnose.run_one("dynamics", "spring", 1394512750)  # a real miss
    assert not missed.named and not missed.taken_up
    assert missed.left > 0.05  # the baseline's held-out MSE on joint2 is 11 % over the twin's
    table = bench_diagnose.table([held, missed])
    assert "1 taken up by the baseline" in table and "1 of the misses taken up by the baseline" in table


def test_a_hidden_fault_said_as_a_minor_fault_counts_as_found_not_named():
    def outcome(cause, top, minor=()):
        return bench_diagnose.Outcome("kinematics", cause, "m0", 1, top, int(bool(top)), 0.5, 1.0, minor=minor)

    outcomes = [
        outcome("marker_slip", "marker_slip:m0"),  # named
        outcome("marker_outliers", "", minor=("marker_outliers:m0",)),  # found, as issue #31 item 3 asks
        outcome("backlash", ""),  # missed
        outcome(None, ""),  # clean
    ]
    row = bench_diagnose.table(outcomes).splitlines()[-1]
    assert "**33%** (goal ≥ 90 %); 67% found, +1 hidden faults said as minor faults" in row
