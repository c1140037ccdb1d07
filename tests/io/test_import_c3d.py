"""`diegocal import` of C3D motion capture (written here with ezc3d): labels, rate, units, gaps."""

import numpy as np
import pytest

from diegocal.errors import LogFormatError
from diegocal.io.importers import MapError, import_log, parse_map
from tests.io.labfiles import write_c3d

LABELS = ["LASI", "RASI", "HAND"]


@pytest.fixture
def trial(tmp_path):
    """100 Hz, first frame 20, markers in mm; HAND unseen in frames 5-8, RASI in frame 0."""
    T = 40
    xyz = np.random.default_rng(0).normal(scale=300.0, size=(T, 3, 3))
    xyz[5:9, 2] = np.nan
    xyz[0, 1] = np.nan
    analog = np.column_stack([np.arange(4 * T) * 0.25, np.full(4 * T, 2.5)])  # 400 Hz
    path = write_c3d(tmp_path / "trial.c3d", LABELS, xyz, rate=100.0, unit="mm", first_frame=20,
                     analogs=(["pot_elbow", "pot_knee"], analog, ["V", "mV"]))
    return path, xyz


def test_markers_come_in_metres_with_gaps_as_nan_on_the_mocap_clock(trial):
    path, xyz = trial
    result = import_log([path])
    log = result.log
    assert list(log.streams) == ["markers"] and log.streams["markers"].names == tuple(LABELS)
    np.testing.assert_allclose(log.streams["markers"].data, xyz / 1000.0, rtol=1e-6)  # C3D stores float32
    assert np.isnan(log.streams["markers"].data[5:9, 2]).all() and np.isnan(log.streams["markers"].data[0, 1]).all()
    assert np.isfinite(log.streams["markers"].data[9:, 2]).all()
    np.testing.assert_allclose(log.time, (20 + np.arange(40)) / 100.0)
    assert log.rate_hz == 100.0
    assert "trial.c3d's time stamps (100 Hz)" in result.clock
    assert any("analogs not imported" in n for n in result.notes)


def test_marker_names_mapped_and_analogs_read_at_mocap_frames(trial):
    path, xyz = trial
    mapping = parse_map({"streams": {
        "markers": {"columns": {"LASI": "pelvis_l", "HAND": "hand"}},
        "pots": {"table": "analogs", "columns": {"pot_elbow": "elbow", "pot_knee": "knee"}}}})
    result = import_log([path], mapping)
    log = result.log
    assert log.streams["markers"].names == ("pelvis_l", "hand")
    np.testing.assert_allclose(log.streams["markers"].data[:, 1], xyz[:, 2] / 1000.0, rtol=1e-6)
    # analog sample 4k is mocap frame k; a pot in mV is brought to V beside the pot in V (issue #32)
    np.testing.assert_allclose(log.streams["pots"].data[:, 0], np.arange(40) * 1.0)
    np.testing.assert_allclose(log.streams["pots"].data[:, 1], 2.5e-3)
    assert ("pots", "from trial.c3d", 2, "V/mV -> V") in result.streams


def test_a_misspelt_label_gets_a_close_match(trial):
    path, _ = trial
    with pytest.raises(MapError, match="no column 'LASY' .* did you mean 'LASI'"):
        import_log([path], parse_map({"streams": {"markers": {"columns": ["LASY"]}}}))
    with pytest.raises(MapError, match="no table 'analog' .* did you mean 'analogs'"):
        import_log([path], parse_map({"streams": {"pots": {"table": "analog", "columns": ["pot_knee"]}}}))


def test_mocap_plus_a_faster_csv_meet_on_the_mocap_clock(trial, tmp_path):
    path, _ = trial
    t = 0.1 + np.arange(0, 2000) * 0.0005  # 2 kHz pots, starting before the capture
    rows = "\n".join(f"{float(x)!r},{float(3 * x - 1)!r}" for x in t)
    (tmp_path / "pots.csv").write_text("time,pots.p\n" + rows + "\n")
    log = import_log([path, tmp_path / "pots.csv"]).log
    np.testing.assert_allclose(log.time, (20 + np.arange(40)) / 100.0)  # the C3D decides the clock
    np.testing.assert_allclose(log.streams["pots"].column("p"), 3 * log.time - 1, atol=1e-12)


def test_no_unit_in_the_file_needs_one_in_the_map(tmp_path):
    xyz = np.ones((5, 1, 3))
    path = write_c3d(tmp_path / "nounit.c3d", ["M"], xyz, rate=50.0, unit=None)
    with pytest.raises(MapError, match="the file states no unit for marker 'M'; give `unit:`"):
        import_log([path])
    log = import_log([path], parse_map({"streams": {"markers": {"unit": "cm"}}})).log
    np.testing.assert_allclose(log.streams["markers"].data, 0.01)


def test_a_broken_c3d_is_one_line(tmp_path):
    (tmp_path / "broken.c3d").write_bytes(b"\x02\x50" + b"\x00" * 100)
    with pytest.raises(LogFormatError, match="broken.c3d: not a readable C3D file") as err:
        import_log([tmp_path / "broken.c3d"])
    assert "\n" not in str(err.value)


def test_a_truncated_c3d_is_refused_unless_allowed(tmp_path, caplog):
    # the case: the header says 2000 frames, the file is cut and ezc3d returns 577 silently
    full = write_c3d(tmp_path / "t.c3d", ["m1", "m2"], np.ones((2000, 2, 3)), rate=100.0)
    (tmp_path / "cut.c3d").write_bytes(full.read_bytes()[:20000])
    with pytest.raises(LogFormatError, match=r"cut.c3d: truncated: the header announces 2000 frames \(20 s\), "
                                             r"the file holds 577 .*allow_truncated") as err:
        import_log([tmp_path / "cut.c3d"])
    assert "\n" not in str(err.value)
    with caplog.at_level("WARNING", logger="diegocal"):
        log = import_log([tmp_path / "cut.c3d"], parse_map({"sources": {"cut": {"allow_truncated": True}}})).log
    assert log.n_samples == 577
    assert any("announces 2000 frames" in r.getMessage() and "577 frames read" in r.getMessage()
               for r in caplog.records)
    assert import_log([full]).log.n_samples == 2000  # a whole file says nothing
