"""Does `diagnose --domain pneumatics` say `unexplained` (or nothing) rather than a wrong name when a
valve-chamber system misbehaves in a way no cause of its vocabulary describes? (issue #31, item 1,
pneumatics)

Each log is a 60-s session of the independent thin-plate generator (the four-chamber robot of
bench_pneumatic_offsim) with one shape of :mod:`experiments.pneumatic_oov` on one chamber: a
pressure sensor's span error, its zero drifting over the session, a sensor lagging through a
first-order filter, a valve's spool with play. A log is *misnamed* when any finding names a cause
other than ``unexplained``, except a lasting ``supply_droop`` on a span error's chamber that says
the span error it equals (:func:`acceptable`); *unexplained* counts the logs with an
``unexplained`` finding on the affected chamber. Goal: ≥ 90 % not misnamed. The
shapes are built from the generator's ``/truth``; the diagnosis never sees it.

    python bench/bench_pneumatic_oov.py --logs 6 --jobs 2 --verbose
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from bench_diagnose_kinematics_oov import bench_main  # noqa: E402

from experiments import pneumatic_generator as gen  # noqa: E402
from experiments.pneumatic_oov import SHAPES, add_shape  # noqa: E402


def run_one(task) -> dict:
    """Diagnose one log with the defaults; the findings as (cause, chamber)."""
    from diegocal.diagnose import DiagnoseOptions, diagnose
    from diegocal.robot import load_robot

    shape, seed = task
    log, chamber, size = add_shape(shape, seed)
    start = time.perf_counter()
    result = diagnose(log.without_truth(), load_robot(gen.ROBOT_DIR), DiagnoseOptions(domain="pneumatics"))
    found = [(f.cause, f.channel) for f in result.findings]
    named_ok = [acceptable(shape, chamber, f) for f in result.findings]
    return {
        "shape": shape,
        "seed": seed,
        "channel": chamber,
        "ratio": size,
        "findings": found,
        "misnamed": any(c != "unexplained" and not ok for (c, _), ok in zip(found, named_ok, strict=True)),
        "unexplained": ("unexplained", chamber) in found,
        "named_ok": any(named_ok),
        "seconds": time.perf_counter() - start,
    }


def acceptable(shape: str, chamber: str, finding) -> bool:
    """A finding that names ``shape`` on its chamber: a lasting supply sag written with the span
    error it equals (``extra.span_error``: to eq. 4.10 the two are one model) for a span error."""
    return (shape == "span_error" and finding.cause == "supply_droop" and finding.channel == chamber
            and "span_error" in finding.term.extra)


def main(argv=None) -> int:
    return bench_main(argv, __doc__, SHAPES, run_one, "size (k - 1, kPa, s, V)")


if __name__ == "__main__":
    raise SystemExit(main())
