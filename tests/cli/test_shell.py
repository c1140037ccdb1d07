"""The CLI shell: inspect, report, predict dispatch; bad input gives one line and exit 1."""

import numpy as np
import pytest
from typer.testing import CliRunner

from diegocal.cli import app
from diegocal.cli.testing import one_line_error
from diegocal.io import Log, make_stream, save_log

runner = CliRunner()


@pytest.fixture
def log_file(tmp_path):
    T = 50
    markers = np.random.default_rng(0).normal(size=(T, 2, 3))
    markers[10:20, 1] = np.nan  # an occlusion run
    log = Log(
        np.arange(T) * 0.01,
        {"pots": make_stream(["p1", "p2"], np.ones((T, 2))), "markers": make_stream(["m1", "m2"], markers)},
        robot="diego",
        rate_hz=100.0,
    )
    path = tmp_path / "run.h5"
    save_log(log, path)
    return path


def test_inspect_describes_streams_and_occlusion(log_file):
    result = runner.invoke(app, ["inspect", str(log_file)])
    assert result.exit_code == 0, result.output
    assert "duration=0.490 s" in result.output and "rate=100 Hz" in result.output
    assert "m2" in result.output and "20.0" in result.output  # 10 of 50 samples occluded
    assert "p1" in result.output


def test_inspect_shows_where_a_log_has_nan_and_that_fits_will_refuse_it(tmp_path):
    T = 20
    tau = np.ones((T, 2))
    tau[[3, 4], 1] = np.nan  # two dropped torque samples
    path = tmp_path / "nan.h5"
    save_log(Log(np.arange(T) * 0.01, {"tau": make_stream(["j1", "j2"], tau)}, robot="x", nan_ok=True), path)
    result = runner.invoke(app, ["inspect", str(path)])
    assert result.exit_code == 0, result.output
    assert "10.0" in result.output  # j2: 2 of 20 samples NaN
    assert "warning: NaN in stream(s) tau" in result.output
    assert "[truth: yes]" not in result.output
    refused = runner.invoke(app, ["sgp-fit", str(path), "--robot", "arm3", "--model", "pr"])
    assert refused.exit_code == 1 and "NaN or infinite value at sample 3" in one_line_error(refused)


def test_inspect_says_a_simulated_log_has_truth(tmp_path):
    path = tmp_path / "sim.h5"
    runner.invoke(app, ["simulate", "dynamics", "--robot", "pendulum", "--duration", "1", "-o", str(path), "-q"])
    result = runner.invoke(app, ["inspect", str(path)])
    assert result.exit_code == 0 and "[truth: yes]" in result.output  # not eaten as rich markup


@pytest.mark.parametrize(
    "content, message",
    [
        (None, "no such file"),
        (b"not a log at all", "not a diegocal log"),
    ],
)
def test_inspect_bad_files(tmp_path, content, message):
    path = tmp_path / "x.dat"
    if content is not None:
        path.write_bytes(content)
    assert message in one_line_error(runner.invoke(app, ["inspect", str(path)]))


def test_inspect_invalid_csv(tmp_path):
    path = tmp_path / "x.csv"
    path.write_text("time,pots.a\n0,1\n0,1\n")
    assert "not strictly increasing" in one_line_error(runner.invoke(app, ["inspect", str(path)]))


def test_report_writes_pdf_with_title_and_log_pages(log_file, tmp_path):
    out = tmp_path / "r.pdf"
    result = runner.invoke(app, ["report", str(log_file), "-o", str(out)])
    assert result.exit_code == 0, result.output
    data = out.read_bytes()
    assert data.startswith(b"%PDF")
    assert data.count(b"/Type /Page\n") + data.count(b"/Type /Page ") >= 1  # the log's page(s); one result: no contents


def test_report_default_output_beside_first_result(log_file):
    result = runner.invoke(app, ["report", str(log_file)])
    assert result.exit_code == 0, result.output
    assert (log_file.parent / "run.report.pdf").exists()


def test_report_unknown_result_writes_nothing(tmp_path, log_file):
    junk = tmp_path / "notes.txt"
    junk.write_text("hi")
    out = tmp_path / "r.pdf"
    line = one_line_error(runner.invoke(app, ["report", str(log_file), str(junk), "-o", str(out)]))
    assert "not a result diegocal can report" in line
    assert not out.exists()


def test_predict_rejects_unknown_model(tmp_path, log_file):
    model = tmp_path / "m.yaml"
    model.write_text("something: 1\n")
    assert "not a fitted diegocal model" in one_line_error(runner.invoke(app, ["predict", str(model), str(log_file)]))


def test_invalid_yaml_model(tmp_path, log_file):
    model = tmp_path / "m.yaml"
    model.write_text("a: [1, 2\n")
    assert "not valid YAML" in one_line_error(runner.invoke(app, ["predict", str(model), str(log_file)]))


@pytest.mark.parametrize(
    "args, needle",
    [
        (["stac"], "Missing argument"),
        (["simulate", "dynamics", "--duration", "abc", "-o", "x.h5"], "--duration"),
        (["pneumatic-fit", "x.h5", "--starts", "0"], "--starts"),
        (["nosuch"], "No such command"),
    ],
)
def test_usage_errors_are_one_line_with_exit_2(args, needle):
    """A bad option value or a missing argument: one line naming it, exit 2 (usage), not a box."""
    result = runner.invoke(app, args)
    line = one_line_error(result)
    assert needle in line and line.startswith("error: diegocal") and result.exit_code == 2


def test_no_arguments_prints_the_help():
    result = runner.invoke(app, [])
    assert result.exit_code == 0 and "Usage" in result.output and "sgp-fit" in result.output
