"""`diegocal sgp-fit` when an ML-II run stops at its iteration cap before its tolerance (#31 item 6):
sgp.yaml says ``converged: false`` with the runs and how many the cap stopped, a warning says so in
words, the exit status is 1 unless ``--allow-unconverged``, and `batch` counts the log failed. The
cap is cut to one iteration here (the default is 200)."""

import pytest
from typer.testing import CliRunner

from diegocal.cli import app
from diegocal.io import load_yaml, save_log

runner = CliRunner()


@pytest.fixture
def log_path(arm2, simulate, tmp_path):
    log, _ = simulate(arm2, T=120, seed=0)
    path = tmp_path / "train.h5"
    save_log(log, path)
    return path


def _fit(path, robot_dir, out, *extra):
    return runner.invoke(app, ["sgp-fit", str(path), "--robot", str(robot_dir), "-m", "pr", "-q", "-o", str(out),
                               *extra])


def test_a_run_at_its_cap_exits_1_and_says_so(log_path, arm2_dir, tmp_path):
    r = _fit(log_path, arm2_dir, tmp_path / "a.sgp", "--max-iterations", "1")
    words = " ".join(r.output.split())
    assert r.exit_code == 1, r.output
    assert "warning: ML-II:" in words and "stopped at their iteration cap (1) before their tolerance" in words
    assert "--allow-unconverged" in words and "Traceback" not in words
    s = load_yaml(tmp_path / "a.sgp" / "sgp.yaml")
    assert s["converged"] is False and 0 < s["ml2_runs"]["stopped_at_cap"] <= s["ml2_runs"]["runs"]
    r = _fit(log_path, arm2_dir, tmp_path / "b.sgp", "--max-iterations", "1", "--allow-unconverged")
    assert r.exit_code == 0 and "iteration cap" in r.output


def test_a_converged_fit_says_nothing(log_path, arm2_dir, tmp_path):
    r = _fit(log_path, arm2_dir, tmp_path / "a.sgp")
    assert r.exit_code == 0 and "converge" not in r.output and "cap" not in r.output, r.output
    s = load_yaml(tmp_path / "a.sgp" / "sgp.yaml")
    assert s["converged"] is True and s["ml2_runs"]["runs"] > 0 and s["ml2_runs"]["stopped_at_cap"] == 0


def test_batch_counts_an_unconverged_fit_failed(log_path, arm2_dir, tmp_path):
    from diegocal.batch import BatchOptions, job_args, plan_batch, run_job

    extra = ("--robot", str(arm2_dir), "-m", "pr", "--max-iterations", "1")
    job = plan_batch("sgp-fit", log_path, BatchOptions(output_dir=tmp_path, extra=extra)).jobs[0]
    outcome = run_job(job, job_args(job))
    assert outcome.failed and "iteration cap" in outcome.message, outcome.message
    options = BatchOptions(output_dir=tmp_path, extra=(*extra, "--allow-unconverged"), force=True)
    job = plan_batch("sgp-fit", log_path, options).jobs[0]
    outcome = run_job(job, job_args(job))
    assert not outcome.failed, outcome.message


def test_prgp_counts_its_pr_stage_too(arm2, simulate, tmp_path):
    """PRGP learns PR's hyperparameters, then the GP's on its residual: both stages' runs count;
    a model restored from its files ran none and says nothing."""
    from diegocal.api import SGP
    from diegocal.sgp import SGPOptions
    from diegocal.sgp.store import load_model

    log, _ = simulate(arm2, T=120, seed=0)
    fitted = SGP(SGPOptions(kind="prgp")).fit(log, arm2)
    model = fitted.model_
    pr, gp = model.pr_.ml2_runs_, model.gp_.ml2_runs_
    assert pr[0] > 0 and gp[0] > 0 and model.ml2_runs_ == (pr[0] + gp[0], pr[1] + gp[1])
    assert model.converged_ is True
    fitted.save(tmp_path / "m.sgp")
    assert load_yaml(tmp_path / "m.sgp" / "sgp.yaml")["ml2_runs"]["runs"] == pr[0] + gp[0]
    assert load_model(tmp_path / "m.sgp").converged_ is None


def test_a_cap_below_one_iteration_is_a_usage_error(log_path, arm2_dir, tmp_path):
    """``--max-iterations 0``: one usage-error line, exit 2, nothing written."""
    from diegocal.cli.testing import one_line_error

    r = _fit(log_path, arm2_dir, tmp_path / "a.sgp", "--max-iterations", "0")
    assert r.exit_code == 2 and "--max-iterations" in one_line_error(r), r.output
    assert not (tmp_path / "a.sgp").exists()
