"""CLI of the pneumatic domain end to end, and its one-line errors."""

import numpy as np
import pytest
from typer.testing import CliRunner

from diegocal.cli import app
from diegocal.cli.testing import one_line_error
from diegocal.io import load_log, load_yaml, make_stream, save_log

runner = CliRunner()


@pytest.fixture(scope="module")
def files(tmp_path_factory, train_log):
    d = tmp_path_factory.mktemp("pneu_cli")
    save_log(train_log.slice(0, 3000), d / "train.h5")
    return d


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def test_simulate_fit_merge_predict_report_end_to_end(tmp_path, robot_dir):
    log = tmp_path / "sim.h5"
    r = invoke(
        "simulate",
        "pneumatics",
        "--robot",
        robot_dir,
        "-o",
        log,
        "--duration",
        8,
        "--sessions",
        2,
        "--substeps",
        5,
        "--seed",
        1,
        "--effect",
        "chamber_leak:elbow.ext",
    )
    assert r.exit_code == 0, r.output
    assert "chamber_leak" in r.output and load_log(log).truth.effects[0]["channel"] == "elbow.ext"
    for name, out in (("shoulder.flex", "a.yaml"), ("elbow.ext", "b.yaml")):
        r = invoke(
            "pneumatic-fit",
            log,
            "--robot",
            robot_dir,
            "--chamber",
            name,
            "-o",
            tmp_path / out,
            "-q",
        )
        assert r.exit_code == 0, r.output
    r = invoke(
        "pneumatic-merge", tmp_path / "a.yaml", tmp_path / "b.yaml", "-o", tmp_path / "all.yaml"
    )
    assert r.exit_code == 0, r.output
    merged = load_yaml(tmp_path / "all.yaml")
    assert list(merged["chambers"]) == ["shoulder.flex", "elbow.ext"]
    entry = merged["chambers"]["elbow.ext"]
    assert {"baseline", "c_b", "c_s", "c_gamma", "cost", "n_samples", "drift_2s"} <= set(entry)
    c7 = next(t for t in entry["baseline"] if t["cause"] == "valve_rate")["parameters"]["c7"]
    assert set(c7) == {"value", "stderr", "unit"} and c7["unit"] == "1/(s V)"
    assert merged["meta"]["log"].endswith("sim.h5")
    r = invoke("predict", tmp_path / "all.yaml", log, "-o", tmp_path / "pred.h5")
    assert r.exit_code == 0, r.output
    assert "median / max" in r.output
    pred = load_log(tmp_path / "pred.h5")
    assert pred.streams["pressure"].names == ("shoulder.flex", "elbow.ext")
    measured = load_log(log).streams["pressure"].select(["elbow.ext"]).data[:, 0]
    assert (
        np.sqrt(np.mean((pred.streams["pressure"].data[:, 1] - measured) ** 2)) < 52.0
    )  # < 10 % span
    r = invoke("report", tmp_path / "all.yaml", "-o", tmp_path / "report.pdf")
    assert r.exit_code == 0, r.output
    assert (tmp_path / "report.pdf").stat().st_size > 10_000


def test_fit_all_skips_a_chamber_that_never_moves(files, robot_dir, tmp_path):
    log = load_log(files / "train.h5")
    p = log.streams["pressure"].data.copy()
    p[:, 2] = 100.0  # elbow.flex: the valve never moved the pressure
    save_log(
        log.with_streams(pressure=make_stream(log.streams["pressure"].names, p)), tmp_path / "x.h5"
    )
    r = invoke("pneumatic-fit", tmp_path / "x.h5", "--robot", robot_dir, "--all", "-j", 2)
    assert r.exit_code == 0, r.output
    assert "elbow.flex not fitted" in r.output and "unidentifiable" in r.output
    out = load_yaml(tmp_path / "x.pneumatic.yaml")  # DESIGN.md default output name
    assert set(out["chambers"]) == {"shoulder.flex", "shoulder.ext", "elbow.ext"}
    assert "unidentifiable" in out["meta"]["skipped"]["elbow.flex"]


def test_fit_errors_are_one_line(files, robot_dir, tmp_path):
    log = files / "train.h5"
    msg = one_line_error(
        invoke("pneumatic-fit", log, "--robot", robot_dir, "--chamber", "knee.flex")
    )
    assert "chamber 'knee.flex' is not in sensors.yaml" in msg
    msg = one_line_error(invoke("pneumatic-fit", log, "--robot", robot_dir))
    assert "--chamber NAME" in msg and "--all" in msg
    # the log names its robot by directory (not bundled): no --robot needed (issue #15)
    res = invoke("pneumatic-fit", log, "--chamber", "elbow.ext", "-o", tmp_path / "ok.yaml", "-q")
    assert res.exit_code == 0, res.output
    assert load_yaml(tmp_path / "ok.yaml")["robot"]["dir"] == str(robot_dir.resolve())
    data = load_log(log)
    u = data.streams["valve"].data.copy()
    u[5, 3] = -1.0
    save_log(
        data.with_streams(valve=make_stream(data.streams["valve"].names, u)), tmp_path / "bad.h5"
    )
    msg = one_line_error(
        invoke("pneumatic-fit", tmp_path / "bad.h5", "--robot", robot_dir, "-c", "elbow.ext")
    )
    assert "outside the valve's range" in msg
    no_p = data.without_truth()
    no_p = type(no_p)(
        no_p.time, {k: v for k, v in no_p.streams.items() if k != "pressure"}, robot=no_p.robot
    )
    save_log(no_p, tmp_path / "nop.h5")
    msg = one_line_error(
        invoke("pneumatic-fit", tmp_path / "nop.h5", "--robot", robot_dir, "--all")
    )
    assert "no 'pressure' stream" in msg


def test_merge_and_simulate_errors_are_one_line(files, robot_dir, tmp_path):
    r = invoke(
        "pneumatic-fit",
        files / "train.h5",
        "--robot",
        robot_dir,
        "-c",
        "elbow.ext",
        "-o",
        tmp_path / "a.yaml",
    )
    assert r.exit_code == 0, r.output
    msg = one_line_error(
        invoke(
            "pneumatic-merge", tmp_path / "a.yaml", tmp_path / "a.yaml", "-o", tmp_path / "m.yaml"
        )
    )
    assert "fitted in both" in msg
    msg = one_line_error(
        invoke(
            "simulate",
            "pneumatics",
            "--robot",
            robot_dir,
            "-o",
            tmp_path / "s.h5",
            "--effect",
            "backlash",
        )
    )
    assert "not a pneumatics effect" in msg
    msg = one_line_error(
        invoke(
            "simulate",
            "pneumatics",
            "--robot",
            robot_dir,
            "-o",
            tmp_path / "s.h5",
            "--experiment",
            "wild",
        )
    )
    assert "'wild' is not one of" in msg


def test_the_library_takes_one_chamber_by_its_name():
    """``Pneumatic(chambers="r_elbow.flex")`` fits that chamber (a string was read as its letters:
    "chamber 'r' is not in sensors.yaml")."""
    from pathlib import Path

    import diegocal.api as dc

    log = Path(__file__).resolve().parents[2] / "sample_data" / "diego_pneumatics.h5"
    fitted = dc.Pneumatic(chambers="r_elbow.flex").fit(log)
    assert list(fitted.fits_) == ["r_elbow.flex"]
