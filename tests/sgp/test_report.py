"""The sgp report section: recognises model directories and dynamics predictions (not plain logs)
and draws their pages."""

import re

import numpy as np
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


def test_a_prediction_log_gets_its_heldout_coverage_page(arm2, simulate, tmp_path):
    """`predict`'s log for a dynamics model is reported with nMSE and ±2σ coverage per joint."""
    log, _ = simulate(arm2, T=60, seed=0)
    held, _ = simulate(arm2, T=40, seed=1)
    save_log(held, tmp_path / "held.h5")
    fit_dynamics(log, arm2, SGPOptions(kind="pr")).save(tmp_path / "pr.sgp")
    r = runner.invoke(
        app, ["predict", str(tmp_path / "pr.sgp"), str(tmp_path / "held.h5"), "-o", str(tmp_path / "p.h5")]
    )
    assert r.exit_code == 0, r.output
    assert "within ±2σ" in r.output
    assert section_for(tmp_path / "p.h5").name == "sgp prediction"
    assert section_for(tmp_path / "held.h5").name == "log"  # a log without a prediction stays a log
    from diegocal.io import load_log
    from diegocal.report.sgp import heldout_score

    sc = heldout_score(load_log(tmp_path / "p.h5"))
    assert sc.channels == tuple(arm2.joint_names) and np.all((sc.coverage >= 0) & (sc.coverage <= 1))
    out = tmp_path / "r.pdf"
    r = runner.invoke(app, ["report", str(tmp_path / "p.h5"), "-o", str(out), "-q"])
    assert r.exit_code == 0, r.output
    assert len(re.findall(rb"/Type\s*/Page\b(?!s)", out.read_bytes())) == 1 + 1  # table, bands (one result: no front page)
