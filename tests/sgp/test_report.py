"""The sgp report section: recognises model directories (not plain logs) and draws its pages."""

import re

from typer.testing import CliRunner

from diegocal.cli import app
from diegocal.io import save_log
from diegocal.report.registry import section_for
from diegocal.sgp import SGPOptions, fit_dynamics

runner = CliRunner()


def test_report_on_a_comparison_directory(arm2, simulate, tmp_path):
    log, _ = simulate(arm2, T=60, seed=0)
    save_log(log, tmp_path / "train.h5")
    results = tmp_path / "results"
    for kind in ("pr", "sgp"):
        fit_dynamics(log, arm2, SGPOptions(kind=kind, maxiter=20)).save(results / f"{kind}.sgp")
    assert section_for(results / "sgp.sgp").name == "sgp"
    assert section_for(results).name == "sgp"
    assert section_for(tmp_path / "train.h5").name == "log"  # plain logs stay with the log section
    out = tmp_path / "r.pdf"
    r = runner.invoke(app, ["report", str(results), str(results / "pr.sgp"), "-o", str(out), "-q"])
    assert r.exit_code == 0, r.output
    data = out.read_bytes()
    assert data.startswith(b"%PDF")
    # contents + 2 section openings (plain words, nMSE table) + comparison + 2 models × (summary, fit,
    # uncertainty) + pr again × 3
    assert len(re.findall(rb"/Type\s*/Page\b(?!s)", data)) == 1 + 2 + 1 + 3 * 3


def test_empty_directory_is_not_an_sgp_result(tmp_path):
    (tmp_path / "nothing").mkdir()
    sec = section_for(tmp_path / "nothing")
    assert sec is None or sec.name != "sgp"
