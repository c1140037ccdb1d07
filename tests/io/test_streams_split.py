"""A typo'd stream is said, never silent; a missing one gets the close match; a log splits in two
contiguous parts, written together (issue #15)."""

import logging

import numpy as np
import pytest

from diegocal.errors import LogFormatError, MissingStreamError
from diegocal.io import Log, Truth, load_log, make_stream, save_log, save_logs, split_log


def _log(T=50, streams=("q", "tau")):
    t = np.arange(T) * 0.01
    data = {s: make_stream(["joint1", "joint2"], np.random.default_rng(0).normal(size=(T, 2))) for s in streams}
    truth = Truth(signals={"q": make_stream(["joint1", "joint2"], np.zeros((T, 2)))})
    return Log(t, data, robot="arm3", rate_hz=100.0, truth=truth)


def test_a_csv_column_of_a_misspelt_stream_is_an_error(tmp_path):
    path = tmp_path / "typo.csv"
    path.write_text("time,q.joint1,q.joint2,tau.joint1,tua.joint2\n0,0,0,0,0\n0.01,0,0,0,0\n")
    with pytest.raises(LogFormatError, match="stream 'tua' is not a diegocal stream — did you mean 'tau'"):
        load_log(path)


def test_an_unknown_stream_is_kept_with_one_warning(tmp_path, caplog):
    path = tmp_path / "extra.csv"
    path.write_text("time,q.joint1,current.joint1\n0,0,1\n0.01,0,1\n")
    with caplog.at_level(logging.WARNING, logger="diegocal.io.files"):
        log = load_log(path)
    assert log.has("current")
    assert len(caplog.records) == 1 and "'current'" in caplog.records[0].getMessage()


def test_a_misspelt_hdf5_group_is_an_error(tmp_path):
    log = _log()
    log = Log(log.time, {"q": log.streams["q"], "qdd_": log.streams["tau"]})
    save_log(log, tmp_path / "g.h5")
    with pytest.raises(LogFormatError, match="did you mean 'qdd'"):
        load_log(tmp_path / "g.h5")


def test_a_missing_stream_names_the_close_match():
    log = Log(np.arange(3.0), {"taus": make_stream(["a"], np.zeros((3, 1)))})
    with pytest.raises(MissingStreamError, match="no 'tau' stream .*did you mean 'taus'"):
        log.stream("tau", needed_by="sgp-fit")


@pytest.mark.parametrize("at, unit, k", [(0.8, "fraction", 40), (0.2, "seconds", 20), (0.205, "seconds", 21)])
def test_split_is_contiguous_and_keeps_everything(at, unit, k):
    log = _log()
    train, held = split_log(log, at, unit)
    assert train.n_samples == k and held.n_samples == 50 - k
    np.testing.assert_array_equal(np.concatenate([train.time, held.time]), log.time)
    np.testing.assert_array_equal(held.streams["tau"].data, log.streams["tau"].data[k:])
    assert held.robot == "arm3" and held.rate_hz == 100.0 and held.truth.signals["q"].data.shape == (50 - k, 2)


@pytest.mark.parametrize("at, unit", [(0.0, "fraction"), (1.0, "fraction"), (0.99, "fraction"), (0.49, "seconds"),
                                      (-1, "seconds"), (0.005, "seconds")])
def test_split_refuses_a_cut_outside_or_too_near_an_end(at, unit):
    with pytest.raises(ValueError):
        split_log(_log(), at, unit)


def test_save_logs_leaves_nothing_when_one_fails(tmp_path):
    log = _log()
    with pytest.raises(LogFormatError, match="unknown log suffix"):
        save_logs([(log, tmp_path / "a.h5"), (log, tmp_path / "b.txt")])
    assert list(tmp_path.iterdir()) == []
