"""`diegocal batch`: one command over a folder of logs, twice in a row, locally and on a Dask
LocalCluster; failures of one log are reported in one line and do not stop the others; a job runs
in-process through the library (no `diegocal` subprocess whose text is parsed back), and a failure
is never hidden: a calibration that did not converge, a log that cannot be read (#32)."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import h5py
import numpy as np
import pytest
from typer.testing import CliRunner

from diegocal.batch import COMMANDS, BatchOptions, find_logs, plan_batch, read_table
from diegocal.cli import app
from diegocal.cli.testing import one_line_error
from diegocal.io import save_log
from diegocal.robot import load_robot, resolve_robot_dir
from diegocal.sim.dynamics import DynamicsOptions, simulate_dynamics
from diegocal.sim.kinematics import KinematicsOptions, simulate_kinematics

runner = CliRunner()
REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def source(tmp_path_factory) -> Path:
    """A folder as a lab has it: two kinematic sessions, a dynamic one, notes and a foreign HDF5 file."""
    d = tmp_path_factory.mktemp("logs")
    finger = load_robot(resolve_robot_dir("finger", None))
    for seed in (1, 2):
        options = KinematicsOptions(duration=4.0)
        save_log(simulate_kinematics(finger, options, np.random.default_rng(seed)), d / f"session{seed}.h5")
    pendulum = load_robot(resolve_robot_dir("pendulum", None))
    save_log(simulate_dynamics(pendulum, DynamicsOptions(duration=4.0), np.random.default_rng(3)), d / "swing.h5")
    (d / "notes.csv").write_text("what,when\nnew cable,monday\n")
    with h5py.File(d / "camera.h5", "w") as f:
        f["frames"] = np.zeros(3)
    return d


def _copy(source: Path, tmp_path: Path, names) -> Path:
    d = tmp_path / "logs"
    d.mkdir()
    for n in names:
        shutil.copy2(source / n, d / n)
    return d


def _batch(*args):
    return runner.invoke(app, ["batch", *map(str, args)])


def test_plan_takes_only_the_logs_a_command_can_use(source):
    plan = plan_batch("stac", source)
    assert [j.log.name for j in plan.jobs] == ["session1.h5", "session2.h5"]
    reasons = {p.name: r for p, r in plan.not_applicable.items()}
    assert "needed by stac" in reasons["swing.h5"]
    assert "expected 'diegocal-log'" in reasons["camera.h5"] and "not a diegocal CSV log" in reasons["notes.csv"]
    assert all(r.count("not a diegocal") <= 1 and str(source) not in r for r in reasons.values())  # said once
    diag = plan_batch("diagnose", str(source / "*.h5"))  # a glob; one job per log and domain
    assert {(j.log.name, j.domain) for j in diag.jobs} == {
        ("session1.h5", "kinematics"),
        ("session2.h5", "kinematics"),
        ("swing.h5", "dynamics"),
    }


def test_derived_files_are_never_taken_for_logs(source, tmp_path):
    d = _copy(source, tmp_path, ["session1.h5"])
    for name in ("session1.prediction.h5", "session1.q.h5"):
        shutil.copy2(d / "session1.h5", d / name)  # valid logs, but outputs of diegocal
    (d / "stac.batch.csv").write_text("# diegocal-batch command=stac\nlog,status\n")
    assert [p.name for p in find_logs(d)] == ["session1.h5"]


def test_stac_writes_no_side_file_beside_its_output(source, tmp_path):
    d = _copy(source, tmp_path, ["session1.h5"])
    r = runner.invoke(app, ["stac", str(d / "session1.h5"), "--max-iterations", "3", "--allow-unconverged", "-q"])
    assert r.exit_code == 0, r.output
    assert sorted(p.name for p in d.iterdir()) == ["session1.calib.yaml", "session1.h5"]


def test_batch_twice_in_a_row_with_two_jobs(source, tmp_path):
    d = _copy(source, tmp_path, ["session1.h5", "session2.h5", "swing.h5", "notes.csv"])
    first = _batch("stac", d, "--jobs", "2", "--", "--max-iterations", "5", "--allow-unconverged")
    assert first.exit_code == 0, first.output
    outputs = [d / "session1.calib.yaml", d / "session2.calib.yaml"]
    stamps = [p.stat().st_mtime_ns for p in outputs]
    fields, columns, rows = read_table(d / "stac.batch.csv")
    assert fields["command"] == "stac" and [r["status"] for r in rows] == ["done", "done", *["not applicable"] * 2]
    assert {Path(r["log"]).name for r in rows[2:]} == {"notes.csv", "swing.h5"}  # listed, with why, as on the terminal
    assert {"iterations", "sigma markers [m]", "sigma tendon [V]", "gain fdp [V/m]"} <= set(columns)
    assert all(0 < float(r["sigma markers [m]"]) < 0.01 for r in rows[:2])
    assert (d / "stac.batch.pdf").read_bytes().startswith(b"%PDF")
    # outputs beside the logs are not taken for logs; nothing is redone
    second = _batch("stac", d, "--jobs", "2", "--", "--max-iterations", "5", "--allow-unconverged")
    assert second.exit_code == 0, second.output
    assert [p.stat().st_mtime_ns for p in outputs] == stamps
    assert [r["status"] for r in read_table(d / "stac.batch.csv")[2]][:2] == ["up to date", "up to date"]
    # a log newer than its output is redone, as make would
    os.utime(d / "session2.h5", None)
    third = _batch("stac", d, "--", "--max-iterations", "5", "--allow-unconverged")
    assert [r["status"] for r in read_table(d / "stac.batch.csv")[2]][:2] == ["up to date", "done"], third.output


def test_one_failure_does_not_stop_the_others(source, tmp_path):
    d = _copy(source, tmp_path, ["session1.h5", "session2.h5"])
    with h5py.File(d / "session2.h5", "r+") as f:  # one marker never seen: stac cannot use this log
        data = f["markers/data"][()]
        data[:, 0] = np.nan
        f["markers/data"][...] = data
    out = tmp_path / "out"
    r = _batch("stac", d, "-o", out, "-q", "--", "--max-iterations", "3", "--allow-unconverged")
    assert r.exit_code == 1
    line = one_line_error(r)
    assert "session2.h5" in line and "never seen" in line
    rows = read_table(out / "stac.batch.csv")[2]
    assert [r["status"] for r in rows] == ["done", "failed"] and "never seen" in rows[1]["reason"]
    assert (out / "session1.calib.yaml").exists() and not (out / "session2.calib.yaml").exists()


def test_list_prints_the_logs_for_make(source):
    r = _batch("diagnose", source, "--list", "--", "--domain", "dynamics")
    assert r.exit_code == 0, r.output
    assert r.output.split() == [str(source / "swing.h5")]


def test_usage_and_input_errors(source, tmp_path):
    assert _batch("fly", source).exit_code == 2
    assert _batch("stac", source, "--jobs", "2", "--scheduler", "tcp://127.0.0.1:1").exit_code == 2
    assert _batch("stac", source, "--loss", "huber").exit_code == 2  # options of the command go after --
    (tmp_path / "empty").mkdir()
    assert "no log files" in one_line_error(_batch("stac", tmp_path / "empty"))
    assert "no such folder" in one_line_error(_batch("stac", tmp_path / "nowhere"))
    assert "no log that stac can use" in one_line_error(_batch("stac", source / "swing.h5"))
    assert "needs the fitted model" in one_line_error(_batch("predict", source))


def test_scheduler_runs_the_same_work_on_a_dask_cluster(source, tmp_path):
    distributed = pytest.importorskip("distributed")
    d = _copy(source, tmp_path, ["swing.h5"])
    shutil.copy2(d / "swing.h5", d / "swing2.h5")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False, dashboard_address=None) as c:
        r = _batch("sgp-fit", d, "--scheduler", c.scheduler_address, "-q", "--", "--model", "pr")
        assert r.exit_code == 0, r.output
        rows = read_table(d / "sgp-fit.batch.csv")[2]
        assert [r["status"] for r in rows] == ["done", "done"]
        assert all(float(r["nMSE theta"]) < 0.05 for r in rows)
        again = _batch("sgp-fit", d, "--scheduler", c.scheduler_address, "-q", "--", "--model", "pr")
        assert [r["status"] for r in read_table(d / "sgp-fit.batch.csv")[2]] == ["up to date"] * 2, again.output


def _make(goal: str, logs: Path, out: Path, *extra: str) -> tuple[list[str], dict]:
    if shutil.which("make") is None:
        pytest.skip("no make")
    python = Path(sys.executable)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}
    cmd = ["make", "-s", "-C", str(REPO), "-j2", goal, f"LOGS={logs}", f"BATCH_OUT={out}", *extra]
    return cmd + [f"BIN={python.parent}", "STAMP=", f"DIEGOCAL={python} -m diegocal"], env


def test_make_rules_plan_one_fit_per_log_and_none_when_up_to_date(source, tmp_path):
    """mk/batch.mk, dry run: one stac per kinematic log into BATCH_OUT, none once the outputs are newer."""
    d = _copy(source, tmp_path, ["session1.h5", "session2.h5", "swing.h5"])
    out = tmp_path / "out"
    cmd, env = _make("calibrate", d, out, "-n")
    plan = subprocess.run(cmd, capture_output=True, text=True, env=env, check=False)
    assert plan.returncode == 0, plan.stderr
    fits = [line for line in plan.stdout.splitlines() if " stac " in line and " batch " not in line]
    assert sorted(f.split(" -o ")[1].split()[0] for f in fits) == [
        str(out / "session1.calib.yaml"),
        str(out / "session2.calib.yaml"),
    ]
    out.mkdir()
    for name in ("session1", "session2"):  # outputs newer than their logs: nothing to refit
        (out / f"{name}.calib.yaml").write_text("method: stac\n")
    again = subprocess.run(cmd, capture_output=True, text=True, env=env, check=False)
    assert [line for line in again.stdout.splitlines() if " stac " in line and " batch " not in line] == []
    assert "batch stac" in again.stdout  # the merged table is still written


@pytest.mark.slow
def test_make_calibrate_twice(source, tmp_path):
    """mk/batch.mk: `make -j2 calibrate LOGS=folder` fits every kinematic log once; a rerun fits nothing."""
    d = _copy(source, tmp_path, ["session1.h5", "session2.h5", "swing.h5"])
    out = tmp_path / "out"
    cmd, env = _make("calibrate", d, out, "BATCH_ARGS=--max-iterations 5 --allow-unconverged")
    first = subprocess.run(cmd, capture_output=True, text=True, env=env, check=False)
    assert first.returncode == 0, first.stderr
    fitted = sorted(p.name for p in out.glob("*.calib.yaml"))
    assert fitted == ["session1.calib.yaml", "session2.calib.yaml"]
    stamps = {p: p.stat().st_mtime_ns for p in out.glob("*.calib.yaml")}
    second = subprocess.run(cmd, capture_output=True, text=True, env=env, check=False)
    assert second.returncode == 0, second.stderr
    assert " stac " not in second.stdout.replace("batch stac", "")  # no fit was rerun
    assert {p: p.stat().st_mtime_ns for p in stamps} == stamps
    statuses = [r["status"] for r in read_table(out / "stac.batch.csv")[2]]
    assert statuses == ["up to date", "up to date", "not applicable"]  # swing.h5: no pots, no markers
    assert sorted(p.name for p in d.iterdir()) == ["session1.h5", "session2.h5", "swing.h5"]  # nothing beside the logs


def test_options_reach_the_command(source, tmp_path):
    options = BatchOptions(output_dir=tmp_path, extra=("--alpha", "0.05", "--domain", "kinematics"))
    plan = plan_batch("diagnose", source, options)
    assert [j.log.name for j in plan.jobs] == ["session1.h5", "session2.h5"]
    argv = plan.jobs[0].argv
    assert argv[:4] == (
        "diagnose",
        str(source / "session1.h5"),
        "-o",
        str(tmp_path / "session1.kinematics.diagnosis.yaml"),
    )
    assert argv.count("--domain") == 1 and argv[argv.index("--alpha") + 1] == "0.05" and argv[-1] == "--quiet"
    model = tmp_path / "m.calib.yaml"
    model.write_text("kind: calibration\n")
    plan = plan_batch("predict", source, BatchOptions(model=model))  # a calibration predicts pots+markers logs
    assert [j.argv[:3] for j in plan.jobs] == [("predict", str(model), str(source / f"session{k}.h5")) for k in (1, 2)]
    assert all(model in j.inputs for j in plan.jobs)  # a newer model makes the predictions stale


@pytest.mark.slow
def test_make_identify_and_pneumatic_models_twice_on_a_mixed_folder(source, tmp_path):
    """`make -j2 identify` and `make -j2 pneumatic-models`: per log and per chamber (merged per log);
    the rerun remakes nothing and only rewrites the merged tables."""
    from diegocal.sim.pneumatics import PneumaticSimOptions, simulate_pneumatics
    from tests.pneumatic.conftest import SENSORS, URDF

    d = _copy(source, tmp_path, ["session1.h5", "swing.h5"])
    robot_dir = tmp_path / "tiny_pneu"
    robot_dir.mkdir()
    (robot_dir / "robot.urdf").write_text(URDF)
    (robot_dir / "sensors.yaml").write_text(SENSORS)
    tiny = load_robot(robot_dir)
    save_log(simulate_pneumatics(tiny, PneumaticSimOptions(duration=4.0, seed=1)), d / "air.h5")
    out = tmp_path / "out"
    for goal in ("identify", "pneumatic-models"):
        extra = (f"BATCH_ROBOT={robot_dir}",) if goal == "pneumatic-models" else ()
        cmd, env = _make(goal, d, out, *extra)
        first = subprocess.run(cmd, capture_output=True, text=True, env=env, check=False)
        assert first.returncode == 0, first.stderr
    assert sorted(p.name for p in (out / "air.chambers").glob("*.yaml")) == sorted(
        f"{c.name}.yaml" for c in tiny.sensors.chambers
    )
    assert (out / "air.pneumatic.yaml").exists() and (out / "swing.sgp" / "sgp.yaml").exists()
    stamps = {p: p.stat().st_mtime_ns for p in out.rglob("*.yaml") if "batch" not in p.name}
    for goal in ("identify", "pneumatic-models"):
        extra = (f"BATCH_ROBOT={robot_dir}",) if goal == "pneumatic-models" else ()
        cmd, env = _make(goal, d, out, *extra)
        again = subprocess.run(cmd, capture_output=True, text=True, env=env, check=False)
        assert again.returncode == 0, again.stderr
    assert {p: p.stat().st_mtime_ns for p in stamps} == stamps
    rows = read_table(out / "pneumatic-fit.batch.csv")[2]
    assert [r["status"] for r in rows if r["status"] != "not applicable"] == ["up to date"]


def test_an_unconverged_calibration_is_a_failure(source, tmp_path):
    """#32: a calibration that stopped before it converged counts as failed (it used to be "done",
    "failed 0"), in the count, the table and the exit status, also when it is up to date; its numbers
    stay in the table. --allow-unconverged (after --) accepts it."""
    d = _copy(source, tmp_path, ["session1.h5"])
    out = tmp_path / "out"
    r = _batch("stac", d, "-o", out, "--", "--max-iterations", "2")
    assert r.exit_code == 1
    assert re.search(r"failed\s+│\s+1", r.output) and re.search(r"done\s+│\s+0", r.output)
    row = read_table(out / "stac.batch.csv")[2][0]
    assert row["status"] == "failed" and "did not converge" in row["reason"] and row["converged"] == "False"
    assert row["iterations"] == "2"
    again = _batch("stac", d, "-o", out, "-q", "--", "--max-iterations", "2")  # up to date: not rerun, still failed
    assert again.exit_code == 1 and "did not converge" in one_line_error(again)
    assert read_table(out / "stac.batch.csv")[2][0]["status"] == "failed"
    allowed = _batch("stac", d, "-o", out, "-q", "--", "--max-iterations", "2", "--allow-unconverged")
    assert allowed.exit_code == 0, allowed.output
    assert read_table(out / "stac.batch.csv")[2][0]["status"] == "up to date"


def test_a_log_that_cannot_be_read_is_a_failure(source, tmp_path):
    """#32: a truncated HDF5 log and a .h5 that is no HDF5 file fail (exit 1, in the table), while
    another program's files are left out as not applicable; no message says the same thing twice."""
    d = _copy(source, tmp_path, ["session1.h5", "camera.h5", "notes.csv"])
    (d / "cut.h5").write_bytes((source / "session2.h5").read_bytes()[:4000])
    (d / "empty.h5").write_bytes(b"")
    out = tmp_path / "out"
    r = _batch("stac", d, "-o", out, "--", "--max-iterations", "3", "--allow-unconverged")
    assert r.exit_code == 1
    rows = {Path(x["log"]).name: x for x in read_table(out / "stac.batch.csv")[2]}
    assert rows["session1.h5"]["status"] == "done"
    assert rows["cut.h5"]["status"] == "failed" and "cannot read HDF5 file" in rows["cut.h5"]["reason"]
    assert rows["empty.h5"]["status"] == "failed" and "not a diegocal log" in rows["empty.h5"]["reason"]
    assert rows["cut.h5"]["output"] == rows["empty.h5"]["output"] == ""  # they wrote nothing
    assert {n for n, x in rows.items() if x["status"] == "not applicable"} == {"camera.h5", "notes.csv"}
    assert set(rows) == {"session1.h5", "cut.h5", "empty.h5", "camera.h5", "notes.csv"}
    failed = [line for line in r.output.splitlines() if line.startswith("failed:")]
    assert len(failed) == 2 and re.search(r"failed\s+│\s+2", r.output)
    for text in [*failed, *(x["reason"] for x in rows.values())]:
        assert text.count("not a diegocal") <= 1 and text.count("cannot read") <= 1, text
    assert _batch("stac", d, "--list").output.split() == [str(d / n) for n in ("cut.h5", "empty.h5", "session1.h5")]


def test_a_job_runs_in_process_and_carries_the_exception_message(source, tmp_path, monkeypatch):
    """#30: a job is the command's job function called with the options its own parser made, and a
    failure's message is the exception's, not text parsed back from a `diegocal` process."""
    import subprocess as sp

    from diegocal.batch import job_args, run_job
    from diegocal.cli.stac_cmd import StacArgs, run_stac
    from diegocal.errors import DiegocalError, OptionError

    def no_process(*args, **kwargs):
        raise AssertionError("batch started a process")

    monkeypatch.setattr(sp, "run", no_process)
    monkeypatch.setattr(sp, "Popen", no_process)
    d = _copy(source, tmp_path, ["session1.h5", "swing.h5"])
    job = plan_batch("stac", d, BatchOptions(extra=("--loss", "huber", "--max-iterations", "3"))).jobs[0]
    args = job_args(job)
    assert isinstance(args, StacArgs) and (args.loss, args.max_iterations, args.quiet) == ("huber", 3, True)
    assert run_job(job, args).message.startswith("the stac fit did not converge")  # what it wrote says so
    swing = plan_batch("sgp-fit", d).jobs[0]
    wrong = replace(job, log=swing.log, argv=("stac", str(swing.log), "-o", str(tmp_path / "s.calib.yaml")))
    with pytest.raises(DiegocalError) as raised:
        run_stac(job_args(wrong))
    outcome = run_job(wrong)
    assert outcome.failed and outcome.message == str(raised.value) and "needed by stac" in outcome.message
    with pytest.raises(OptionError, match="'cauchy' is not one of"):  # the command's own parser
        plan_batch("stac", d, BatchOptions(extra=("--loss", "cauchy")))


def test_make_goes_on_past_a_bad_log_and_writes_the_table(source, tmp_path):
    """#32: `make -j2 calibrate` with one log that cannot be read: the others are fitted, the merged
    table is written (the bad log failed in it) and make exits non-zero."""
    d = _copy(source, tmp_path, ["session1.h5", "session2.h5"])
    (d / "bad.h5").write_bytes((source / "session1.h5").read_bytes()[:4000])
    out = tmp_path / "out"
    cmd, env = _make("calibrate", d, out, "BATCH_ARGS=--max-iterations 3 --allow-unconverged")
    run = subprocess.run(cmd, capture_output=True, text=True, env=env, check=False)
    assert run.returncode != 0
    assert sorted(p.name for p in out.glob("*.calib.yaml")) == ["session1.calib.yaml", "session2.calib.yaml"]
    rows = {Path(r["log"]).name: r["status"] for r in read_table(out / "stac.batch.csv")[2]}
    assert rows == {"bad.h5": "failed", "session1.h5": "up to date", "session2.h5": "up to date"}
    assert "cannot read HDF5 file" in run.stderr


def test_make_one_output_by_its_name(source, tmp_path):
    """#32: `make BATCH_OUT/<log>.calib.yaml` and, for the logs of LOGS, `make out/<log>.calib.yaml`
    (the names README gives) are targets."""
    d = _copy(source, tmp_path, ["session1.h5"])
    for target, extra in ((tmp_path / "b" / "session1.calib.yaml", (f"BATCH_OUT={tmp_path / 'b'}",)),
                          ("out/session1.calib.yaml", ())):
        cmd, env = _make(str(target), d, tmp_path / "b", "-n")
        cmd = [c for c in cmd if not c.startswith("BATCH_OUT=")] + list(extra)
        plan = subprocess.run(cmd, capture_output=True, text=True, env=env, check=False)
        assert plan.returncode == 0, plan.stderr
        assert f"stac {d / 'session1.h5'} -o {target}" in plan.stdout


def test_reading_the_makefile_runs_no_python(tmp_path):
    """#32: a fresh clone has no .venv: `make -n demo` (and every goal that needs no chamber list)
    reads the Makefile without running its Python, so it prints no "python: not found" line."""
    if shutil.which("make") is None:
        pytest.skip("no make")
    nowhere = tmp_path / "no-venv" / "bin"
    for goal in ("demo", "test", "calibrate"):
        run = subprocess.run(
            ["make", "-n", "-C", str(REPO), goal, f"BIN={nowhere}", f"STAMP={tmp_path / 'stamp'}", "DIEGOCAL=true"],
            capture_output=True, text=True, check=False,
        )
        assert run.returncode == 0 and run.stderr == "", (goal, run.stderr)


@pytest.mark.parametrize("command", list(COMMANDS))
def test_each_command_parses_into_its_options_dataclass(command, tmp_path):
    """The options dataclass of every command batch runs has exactly the command's parameters (an
    option added to the command and not to the dataclass fails here, not in a user's batch)."""
    import dataclasses
    import importlib

    from diegocal.batch.jobs import _parse

    spec = COMMANDS[command]
    argv = ("m.yaml", "r.h5") if command == "predict" else ("r.h5",)
    argv += ("--all",) if command == "pneumatic-fit" else ()
    params = _parse(command, (*argv, "-o", str(tmp_path / ("out.h5" if command == "predict" else "out"))))
    cls = getattr(importlib.import_module(spec.module), spec.args)
    assert {f.name for f in dataclasses.fields(cls)} == set(params)
    assert cls(**params).quiet is False
