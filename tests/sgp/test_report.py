"""The sgp report section: recognises model directories and dynamics predictions (not plain logs)
and typesets their pages: a comparison table, per-joint tables with held-out numbers, the identified
parameters with units, figures with captions; no monospace text dump, nothing off the page."""

import re

import numpy as np
import pytest
from typer.testing import CliRunner

from diegocal.cli import app
from diegocal.io import load_log, save_log
from diegocal.report.registry import ReportContext, section_for
from diegocal.report.sgp import heldout_score
from diegocal.report.sgp_text import joint_table, verdict
from diegocal.sgp import SGPOptions, fit_dynamics, load_summary
from diegocal.sgp.store import save_model
from tests.report.checks import check_pages, page_texts

pymupdf = pytest.importorskip("pymupdf")
runner = CliRunner()


def _fonts(document) -> set[str]:
    return {
        span["font"]
        for page in document
        for b in page.get_text("dict")["blocks"]
        for line in b.get("lines", [])
        for span in line["spans"]
    }


def test_report_on_a_comparison_directory(arm2, simulate, tmp_path):
    log, _ = simulate(arm2, T=60, seed=0)
    held, _ = simulate(arm2, T=40, seed=1)
    save_log(log, tmp_path / "train.h5")
    save_log(held, tmp_path / "held.h5")
    results = tmp_path / "results"
    for kind in ("pr", "sgp"):
        save_model(fit_dynamics(log, arm2, SGPOptions(kind=kind, maxiter=20)), results / f"{kind}.sgp")
    assert section_for(results / "sgp.sgp").name == "sgp"
    assert section_for(results).name == "sgp"
    assert section_for(tmp_path / "train.h5").name == "log"  # plain logs stay with the log section
    out = tmp_path / "r.pdf"
    r = runner.invoke(app, ["report", str(results), "--heldout", str(tmp_path / "held.h5"), "-o", str(out), "-q"])
    assert r.exit_code == 0, r.output
    doc = pymupdf.open(out)
    check_pages(doc)
    assert not any("Mono" in f for f in _fonts(doc))  # typeset, no monospace text dump
    pages = page_texts(doc)
    text = " ".join(pages)
    assert "A comparison of 2 torque models" in text and "Lowest nMSE on held-out data (held.h5)" in text
    assert text.count("Comparison per model and joint") == 1  # one comparison table
    for kind in ("pr", "sgp"):
        nmse = load_summary(results / f"{kind}.sgp")["nmse_in_sample"]
        for joint, value in nmse.items():  # each model and joint a row, its numbers from the model
            assert re.search(rf"{kind}\.sgp {joint} {re.escape(f'{value:.3g}')} ", text), (kind, joint)
    assert text.count("Identified parameters") == 2  # each model's base parameters, with units and SE
    for unit in ("kg·m²", "kg·m", "N·m·s/rad", "± SE"):
        assert unit in text
    assert "parametric only" in text or "GP kept as learnt" in text  # the guard's choice in words
    # the guard's evidence: each candidate's cross-validated nMSE, the chosen one starred (sgp only)
    assert text.count("The guard's cross-validation") == 1
    hyper = load_summary(results / "sgp.sgp")["hyperparameters"]
    for joint in ("shoulder", "elbow"):
        chosen = hyper[joint]["guard_validation"][hyper[joint]["guard_choice"]]
        assert f"{chosen:.3g} *" in text, joint
    assert "held-out log (nMSE" in text and "(40 samples)" in text  # held-out bands, sample counts on axes
    assert "Orange dashed: the parametric part alone" in text  # every line explained


def test_empty_directory_is_not_an_sgp_result(tmp_path):
    (tmp_path / "nothing").mkdir()
    sec = section_for(tmp_path / "nothing")
    assert sec is None or sec.name != "sgp"


def test_a_sparse_fit_shows_its_inducing_inputs(arm2, simulate, tmp_path):
    log, _ = simulate(arm2, T=80, seed=3)
    opts = SGPOptions(kind="sgp", maxiter=15, inference="sparse", n_inducing=12, guard=False)
    save_model(fit_dynamics(log, arm2, opts), tmp_path / "m.sgp")
    columns, rows, notes = joint_table([tmp_path / "m.sgp"], ReportContext())
    names = [c.name for c in columns]
    assert "inducing\ninputs" in names and "missed\nvariance" in names
    hyper = load_summary(tmp_path / "m.sgp")["hyperparameters"]
    k = names.index("inducing\ninputs")
    assert [row[k] for row in rows] == [str(hyper[j]["n_inducing"]) for j in arm2.joint_names]
    assert "Missed variance" in notes[0]


def test_a_prediction_log_gets_its_heldout_section(arm2, simulate, tmp_path):
    """`predict`'s log for a dynamics model: an opening in plain words with a verdict, nMSE, RMSE and
    ±2σ coverage per joint in a table, measured vs predicted with the band."""
    log, _ = simulate(arm2, T=60, seed=0)
    held, _ = simulate(arm2, T=40, seed=1)
    save_log(held, tmp_path / "held.h5")
    save_model(fit_dynamics(log, arm2, SGPOptions(kind="pr")), tmp_path / "pr.sgp")
    r = runner.invoke(
        app, ["predict", str(tmp_path / "pr.sgp"), str(tmp_path / "held.h5"), "-o", str(tmp_path / "p.h5")]
    )
    assert r.exit_code == 0, r.output
    assert "within ±2σ" in r.output
    assert section_for(tmp_path / "p.h5").name == "sgp prediction"
    assert section_for(tmp_path / "held.h5").name == "log"  # a log without a prediction stays a log
    sc = heldout_score(load_log(tmp_path / "p.h5"))
    assert sc.channels == tuple(arm2.joint_names) and np.all((sc.coverage >= 0) & (sc.coverage <= 1))
    out = tmp_path / "r.pdf"
    r = runner.invoke(app, ["report", str(tmp_path / "p.h5"), "-o", str(out), "-q"])
    assert r.exit_code == 0, r.output
    doc = pymupdf.open(out)
    check_pages(doc)
    text = " ".join(page_texts(doc))
    assert "Held-out torque prediction: p.h5" in text
    assert "predicted by diegocal predict by model pr.sgp for 40 samples" in text and "Verdict:" in text
    assert "of log held.h5" in text  # the prediction log records what made it (Log.source)
    source = load_log(tmp_path / "p.h5").source
    assert source["model"] == str((tmp_path / "pr.sgp").resolve()) and source["log"] == str(tmp_path / "held.h5")
    for j, e, rmse, c in zip(sc.channels, sc.nmse, sc.rmse, sc.coverage, strict=True):
        row = f"{j} 40 {e:.3g} {rmse:.3g} "
        assert row in text, row
        assert f"{j}: nMSE {e:.3g}, {100 * c:.0f} % inside ±2σ" in text  # each joint's band, titled


def test_verdict_words():
    assert verdict(0.004, 0.95) == "good; ±2σ right"
    assert verdict(0.05, 0.3) == "fair; ±2σ too narrow"
    assert verdict(0.5, 1.0) == "poor; ±2σ too wide"
    assert verdict(2.0) == "useless"


def test_the_joint_table_names_a_cut_gp(arm2, simulate, tmp_path):
    """A joint whose two-stage GP is cut (sgp.yaml hyperparameters.<joint>.region) shows where;
    a hand-edited region that is not a map with a numeric onset shows nothing more."""
    from diegocal.io import load_yaml, save_yaml
    from diegocal.sgp.store import region_text

    log, _ = simulate(arm2, T=80, seed=3)
    save_model(fit_dynamics(log, arm2, SGPOptions(kind="sgp", maxiter=15)), tmp_path / "m.sgp")
    path = tmp_path / "m.sgp" / "sgp.yaml"
    s = load_yaml(path)
    s["hyperparameters"]["shoulder"].update(guard_choice="two-stage", region={"input": "q.shoulder", "onset": 0.5})
    s["hyperparameters"]["elbow"].update(guard_choice="two-stage", region={"onset": "high"})
    save_yaml(s, path)
    _, rows, notes = joint_table([tmp_path / "m.sgp"], ReportContext())
    cells = {row[0]: " ".join(map(str, row)) for row in rows}
    assert any("'cut at q ≥ c'" in n for n in notes)
    assert "two stages, cut at q.shoulder ≥ 0.5 rad" in cells["shoulder"]
    assert "cut at" not in cells["elbow"] and "two stages" in cells["elbow"]
    assert region_text({"region": None}) == ""


def test_a_prediction_log_as_heldout_is_scored_against_its_measured_torque(arm2, simulate, tmp_path):
    """`report MODEL --heldout p.h5` with `predict`'s own output: scored against tau_measured, as
    the measured log is (its tau is the prediction: it once scored nMSE 0 and 100 % coverage)."""
    from diegocal.report.sgp_text import heldout_prediction

    log, _ = simulate(arm2, T=60, seed=0)
    held, _ = simulate(arm2, T=40, seed=1)
    save_log(held, tmp_path / "held.h5")
    save_model(fit_dynamics(log, arm2, SGPOptions(kind="pr")), tmp_path / "pr.sgp")
    args = ["predict", str(tmp_path / "pr.sgp"), str(tmp_path / "held.h5"), "-o", str(tmp_path / "p.h5")]
    r = runner.invoke(app, args)
    assert r.exit_code == 0, r.output
    model = str((tmp_path / "pr.sgp").resolve())
    from_log = heldout_prediction(model, (str(tmp_path / "held.h5"),))
    from_prediction = heldout_prediction(model, (str(tmp_path / "p.h5"),))
    np.testing.assert_allclose(from_prediction.score.nmse, from_log.score.nmse, rtol=1e-9)
    assert np.all(from_prediction.score.nmse > 0)


def test_a_joint_whose_learnt_noise_dwarfs_its_siblings_is_not_called_right():
    """The Panda with a position friction on joint 4, fitted without a GP there: σ_v 2.96 N·m where
    the other joints learnt 0.01. Its band covers the data because it is that wide; the report says
    so rather than only that the band is about right."""
    from diegocal.report.sgp_text import noisy_joints, noisy_words

    hyper = {f"j{i}": {"sigma_v": 0.0104 + 0.0002 * i} for i in range(1, 8)}
    hyper["j4"] = {"sigma_v": 2.96}
    assert list(noisy_joints(hyper)) == ["j4"]
    words = noisy_words(hyper)
    assert "on j4 the noise the model learnt, σ_v 2.96, is 2" in words and "an effect the model lacks" in words
    hyper["j4"] = {"sigma_v": 0.05}  # five times the others: a noisier sensor is plausible
    assert noisy_words(hyper) == ""
    assert noisy_joints({"a": {"sigma_v": 1.0}, "b": {"sigma_v": 0.01}}) == {}  # two joints: no reference
    hyper["j4"] = {"sigma_v": 2.96}
    nmse = {f"j{i}": 0.0002 for i in range(1, 8)}
    nmse["j4"] = 0.2  # the missing friction: its relative error too is far above the others'
    assert list(noisy_joints(hyper, nmse)) == ["j4"]


def test_a_joint_that_carries_more_torque_is_not_called_noisy():
    """A user trial: a clean UR5, the model exact, its shoulder's σ_v 0.294 N·m (the true noise 0.290)
    24 times the other joints' median, every joint's in-sample nMSE 0.0002: noise in N·m that grows
    with the torque a joint carries, not an effect the model lacks."""
    from diegocal.report.sgp_text import noisy_words

    hyper = {"pan": {"sigma_v": 0.012}, "lift": {"sigma_v": 0.294}, "elbow": {"sigma_v": 0.11},
             "w1": {"sigma_v": 0.012}, "w2": {"sigma_v": 0.011}, "w3": {"sigma_v": 0.012}}
    nmse = dict.fromkeys(hyper, 0.0002)
    assert "lift" in noisy_words(hyper) and noisy_words(hyper, nmse) == ""


def test_a_joint_fitted_worse_than_its_mean_is_said_to_be():
    """TIAGo's torso lift: in-sample nMSE 1.78 under PR (its force, 182.5 ± 1.1 N, follows the arm's
    motion less than the shared rigid body predicts). The abstract says the model does worse than
    the mean there; a joint under 1 gets no such sentence."""
    from diegocal.report.sgp_text import worse_than_mean_words

    words = worse_than_mean_words({"torso": 1.78, "arm": 0.04})
    assert "On torso the model does worse than the mean torque" in words and "arm" not in words
    assert worse_than_mean_words({"arm": 0.04}) == ""


def test_a_kept_gp_that_follows_fine_detail_of_the_path_is_said_to():
    """A user trial's Z1 joint 3: the guard kept a two-stage GP whose length-scale in q.joint1 was
    0.066 of its training spread; cross-validated on blocks of one repeating path it gained 20×,
    on another session nothing. The words say the gain may be the path's, and to check it; a
    parametric joint or a smooth GP gets no such sentence."""
    from diegocal.report.sgp_text import fine_inputs, fine_words

    hyper = {
        "joint3": {"guard_choice": "two-stage", "lengthscales_std": {"q.joint1": 0.066, "q.joint3": 2.1}},
        "joint2": {"guard_choice": "parametric", "lengthscales_std": {"q.joint1": 0.01}},
        "joint4": {"guard_choice": "learnt", "lengthscales_std": {"q.joint4": 0.9}},
    }
    assert fine_inputs(hyper) == {"joint3": {"q.joint1": 0.066}}
    words = fine_words(hyper)
    assert "On joint3 the GP kept varies over 0.066 of q.joint1's training spread" in words
    assert "diegocal predict" in words and "joint2" not in words and "joint4" not in words
