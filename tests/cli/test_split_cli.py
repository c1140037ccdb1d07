"""`diegocal split`: two contiguous parts, written together; a bad --at is a usage error (exit 2,
one line)."""

import numpy as np
import pytest
from typer.testing import CliRunner

from diegocal.cli import app
from diegocal.io import Log, load_log, make_stream, save_log

runner = CliRunner()


@pytest.fixture
def log_path(tmp_path):
    T = 200
    log = Log(np.arange(T) * 0.01, {"q": make_stream(["j"], np.arange(T, dtype=float)[:, None])}, robot="arm3")
    save_log(log, tmp_path / "s.h5")
    return tmp_path / "s.h5"


def test_split_writes_train_and_heldout(log_path, tmp_path):
    out = [str(tmp_path / "a.h5"), str(tmp_path / "b.csv")]
    res = runner.invoke(app, ["split", str(log_path), "--at", "0.75", "-o", *out])
    assert res.exit_code == 0, res.output
    a, b = load_log(tmp_path / "a.h5"), load_log(tmp_path / "b.csv")
    assert a.n_samples == 150 and b.n_samples == 50 and b.streams["q"].data[0, 0] == 150.0
    assert a.robot == b.robot == "arm3"


def test_split_defaults_beside_the_log_and_accepts_seconds(log_path):
    res = runner.invoke(app, ["split", str(log_path), "--at", "1.5s", "-q"])
    assert res.exit_code == 0, res.output
    assert load_log(log_path.with_name("s.train.h5")).n_samples == 150
    assert load_log(log_path.with_name("s.heldout.h5")).time[0] == pytest.approx(1.5)


@pytest.mark.parametrize("at", ["abc", "0", "3s", "100%", "99", "-0.5", "0.999"])
def test_bad_at_is_a_usage_error(log_path, tmp_path, at):
    res = runner.invoke(app, ["split", str(log_path), "--at", at, "-o", str(tmp_path / "a.h5"), str(tmp_path / "b.h5")])
    assert res.exit_code == 2, res.output
    lines = [line for line in res.output.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:") and "--at" in lines[0]
    assert not (tmp_path / "a.h5").exists() and not (tmp_path / "b.h5").exists()


def test_outputs_must_differ(log_path):
    res = runner.invoke(app, ["split", str(log_path), "--at", "0.5", "-o", str(log_path), str(log_path) + "x.h5"])
    assert res.exit_code == 2 and "distinct" in res.output
