"""`diegocal pneumatic-fit` when a chamber's least squares stops at its evaluation budget before its
tolerance (#31 item 6): the chamber is written with ``converged: false``, a warning says so in
words, the exit status is 1 unless ``--allow-unconverged``, and `batch` counts the log failed. The
budget is cut to two evaluations here (the bundled sample's 76 chambers converge in 15-32)."""

import pytest
from typer.testing import CliRunner

import diegocal.pneumatic.fit as pneumatic_fit
from diegocal.cli import app
from diegocal.io import load_yaml, save_log
from diegocal.sim.pneumatics import PneumaticSimOptions, simulate_pneumatics
from tests.pneumatic.conftest import write_robot

runner = CliRunner()


@pytest.fixture(scope="module")
def log_path(tmp_path_factory):
    from diegocal.robot import load_robot

    d = tmp_path_factory.mktemp("pneu")
    robot_dir = write_robot(d / "robot")
    log = simulate_pneumatics(load_robot(robot_dir), PneumaticSimOptions(duration=8.0, substeps=5, seed=3))
    path = d / "session.h5"
    save_log(log, path)
    return path, robot_dir


@pytest.fixture()
def small_budget(monkeypatch):
    solve = pneumatic_fit.least_squares
    monkeypatch.setattr(pneumatic_fit, "least_squares", lambda *a, **k: solve(*a, **{**k, "max_nfev": 2}))


def _fit(log_path, out, *extra):
    path, robot_dir = log_path
    return runner.invoke(app, ["pneumatic-fit", str(path), "--robot", str(robot_dir), "-c", "elbow.flex", "-o",
                               str(out), *extra])


def test_a_fit_at_its_budget_exits_1_and_says_so(log_path, tmp_path, small_budget):
    out = tmp_path / "p.yaml"
    r = _fit(log_path, out, "-q")
    words = " ".join(r.output.split())
    assert r.exit_code == 1, r.output
    assert "warning: the fit of chamber(s) elbow.flex stopped at its evaluation budget" in words
    assert "--allow-unconverged" in words and "Traceback" not in words
    assert load_yaml(out)["chambers"]["elbow.flex"]["converged"] is False  # written, and marked
    r = _fit(log_path, tmp_path / "q.yaml", "-q", "--allow-unconverged")
    assert r.exit_code == 0 and "stopped at its evaluation budget" in r.output


def test_a_converged_fit_says_nothing(log_path, tmp_path):
    out = tmp_path / "p.yaml"
    r = _fit(log_path, out, "-q")
    assert r.exit_code == 0 and "converge" not in r.output, r.output
    assert load_yaml(out)["chambers"]["elbow.flex"]["converged"] is True


def test_batch_counts_an_unconverged_fit_failed(log_path, tmp_path, small_budget):
    """The job run in this process (batch's workers are fresh interpreters the budget does not
    reach): what it wrote says it did not converge, so the job fails; accepted with the flag."""
    from diegocal.batch import BatchOptions, job_args, plan_batch, run_job

    path, robot_dir = log_path
    extra = ("--robot", str(robot_dir), "-c", "elbow.flex")
    job = plan_batch("pneumatic-fit", path, BatchOptions(output_dir=tmp_path, extra=extra)).jobs[0]
    outcome = run_job(job, job_args(job))
    assert outcome.failed and "stopped at its evaluation budget" in outcome.message, outcome.message
    job = plan_batch("pneumatic-fit", path, BatchOptions(output_dir=tmp_path, extra=(*extra, "--allow-unconverged"),
                                                          force=True)).jobs[0]
    assert not run_job(job, job_args(job)).failed
