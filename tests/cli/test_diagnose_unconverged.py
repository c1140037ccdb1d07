"""`diegocal diagnose` when a kept fit stops at a cap before its tolerance (#31 item 6):
diagnosis.yaml says ``converged: false`` and what stopped, the command warns and exits 1 unless
``--allow-unconverged``, and the report says it. The fit with the found pot curve is made to say
its refinement stopped at its cap (the adapter's own account of that is tested in
tests/diagnose/test_kinematics_refine.py; the default cap, six steps, is reached on a 10-minute
diego log)."""

import numpy as np
import pytest
from typer.testing import CliRunner

from diegocal.cli import app
from diegocal.diagnose.kinematics import KinematicsAdapter
from diegocal.io import load_yaml, save_log
from diegocal.report.diagnose import summary_lines
from diegocal.robot import load_robot, resolve_robot_dir
from diegocal.sim.effects import parse_effect
from diegocal.sim.kinematics import KinematicsOptions, simulate_kinematics

runner = CliRunner()


@pytest.fixture(scope="module")
def curved(tmp_path_factory):
    robot = load_robot(resolve_robot_dir("finger", None))
    opts = KinematicsOptions(duration=20.0, effects=(parse_effect("sensor_nonlinearity:dip"),))
    path = tmp_path_factory.mktemp("curved") / "c.h5"
    save_log(simulate_kinematics(robot, opts, np.random.default_rng(3)), path)
    return path


def _diagnose(path, out, *extra):
    return runner.invoke(app, ["diagnose", str(path), "--domain", "kinematics", "-o", str(out), "-q", *extra])


def test_a_refinement_stopped_by_its_cap_is_said_and_fails_the_command(curved, tmp_path, monkeypatch):
    stopped = "the found terms' refinement stopped at its cap of 6 step(s) while its last step still moved it"
    monkeypatch.setattr(KinematicsAdapter, "unconverged", staticmethod(lambda f: (stopped,) if f.terms else ()))
    out = tmp_path / "c.diagnosis.yaml"
    r = _diagnose(curved, out)
    words = " ".join(r.output.split())
    assert r.exit_code == 1, r.output
    assert "warning: kinematics diagnosis: with sensor_nonlinearity:dip: the found terms' refinement stopped" in words
    assert "--allow-unconverged" in words and "Traceback" not in words
    d = load_yaml(out)
    assert d["converged"] is False and [f["cause"] for f in d["findings"]] == ["sensor_nonlinearity"]
    assert "Not converged: with sensor_nonlinearity:dip" in " ".join(summary_lines(d))
    r = _diagnose(curved, tmp_path / "d.diagnosis.yaml", "--allow-unconverged")
    assert r.exit_code == 0 and "refinement stopped" in r.output


def test_a_converged_diagnosis_says_nothing(curved, tmp_path):
    out = tmp_path / "c.diagnosis.yaml"
    r = _diagnose(curved, out)
    assert r.exit_code == 0 and "converge" not in r.output, r.output
    d = load_yaml(out)
    assert d["converged"] is True and d["unconverged"] == []
    assert "Not converged" not in " ".join(summary_lines(d))


def test_batch_counts_an_unconverged_diagnosis_failed(curved, tmp_path, monkeypatch):
    """The job run in this process (batch's workers are fresh interpreters the patch does not reach)."""
    from diegocal.batch import BatchOptions, job_args, plan_batch, run_job

    stopped = "STAC stopped after 200 iteration(s), unconverged"
    monkeypatch.setattr(KinematicsAdapter, "unconverged", staticmethod(lambda f: (stopped,)))
    job = plan_batch("diagnose", curved, BatchOptions(output_dir=tmp_path, extra=("--domain", "kinematics"))).jobs[0]
    outcome = run_job(job, job_args(job))
    assert outcome.failed and f"kinematics diagnosis: baseline: {stopped}" in outcome.message, outcome.message


def test_a_dynamics_baseline_whose_ml2_stops_at_its_cap_is_said(tmp_path, monkeypatch):
    """The dynamics baseline (PR: σ_w and σ_v by ML-II) with its L-BFGS-B cut to one iteration:
    the diagnosis says so; with the default cap it converges."""
    from dataclasses import replace

    from diegocal.diagnose import DiagnoseOptions, diagnose
    from diegocal.diagnose.dynamics import DynamicsAdapter
    from diegocal.sim.dynamics import DynamicsOptions, simulate_dynamics

    robot = load_robot(resolve_robot_dir("pendulum", None))
    log = simulate_dynamics(robot, DynamicsOptions(duration=6.0), np.random.default_rng(2))
    options = DiagnoseOptions(domain="dynamics", max_rounds=1)
    assert diagnose(log, robot, options).units[0].unconverged == ()
    made = DynamicsAdapter._options
    monkeypatch.setattr(DynamicsAdapter, "_options", lambda self, kind="pr": replace(made(self, kind), maxiter=1))
    late = diagnose(log, robot, options).units[0].unconverged
    assert late and late[0].startswith("baseline: ML-II: ") and "stopped at their iteration cap" in late[0], late
