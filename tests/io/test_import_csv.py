"""`diegocal import` of CSV exports: rostopic echo -p, diegocal CSV, lab tables with a map."""

import numpy as np
import pytest

from diegocal.errors import InputFileError, LogFormatError
from diegocal.io import Log, make_stream, save_log
from diegocal.io.importers import MapError, UnitError, import_log, parse_map
from tests.io.labfiles import EPOCH_NS, write_rostopic_csv

NAMES = ["shoulder", "elbow"]


def _csv(path, header, rows):
    lines = [",".join(header)] + [",".join(repr(float(v)) if not isinstance(v, str) else v for v in r) for r in rows]
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture
def joint_states(tmp_path):
    rng = np.random.default_rng(0)
    t = np.arange(30) * 0.01
    pos, vel, eff = (rng.normal(size=(30, 2)) for _ in range(3))
    path = write_rostopic_csv(tmp_path / "js.csv", NAMES, t, pos, vel, eff, receive_offset=0.004)
    return path, t, pos, vel, eff


def test_rostopic_joint_states_become_q_qd_tau(joint_states):
    path, t, pos, vel, eff = joint_states
    result = import_log([path])
    log = result.log
    assert list(log.streams) == ["q", "qd", "tau"]
    assert log.streams["q"].names == tuple(NAMES)
    np.testing.assert_array_equal(log.streams["q"].data, pos)
    np.testing.assert_array_equal(log.streams["qd"].data, vel)
    np.testing.assert_array_equal(log.streams["tau"].data, eff)
    np.testing.assert_allclose(log.time - EPOCH_NS * 1e-9, t, atol=1e-6)  # header stamps, ROS time
    assert any("field.header.stamp" in n for n in result.notes)


def test_rostopic_receive_time_and_zero_time(joint_states):
    path, t, *_ = joint_states
    log = import_log([path], parse_map({"sources": {"js": {"stamp": "receive", "zero_time": True}}})).log
    np.testing.assert_allclose(log.time, t, atol=1e-12)  # exact: relative ns before float seconds
    shifted = import_log([path], parse_map({"sources": {"js": {"stamp": "receive", "time_offset": -5.0}}})).log
    np.testing.assert_allclose(shifted.time - (EPOCH_NS * 1e-9 - 5.0), t + 0.004, atol=1e-6)


def test_rostopic_other_topic_by_mapping(tmp_path):
    header = ["%time", "field.layout.data_offset", "field.data0", "field.data1"]
    rows = [[str(EPOCH_NS + k * 10_000_000), 0, 0.1 * k, 2.0] for k in range(5)]
    path = _csv(tmp_path / "pots.csv", header, rows)
    with pytest.raises(MapError, match="nothing to import without a map .*data0"):
        import_log([path])
    log = import_log([path], parse_map({"streams": {"pots": {"columns": {"data0": "p1", "data1": "p2"}}}})).log
    np.testing.assert_allclose(log.streams["pots"].data, [[0.1 * k, 2.0] for k in range(5)])


def test_diegocal_csv_round_trips_with_occluded_markers(tmp_path):
    T = 20
    markers = np.random.default_rng(1).normal(size=(T, 2, 3))
    markers[4:8, 1] = np.nan
    log = Log(np.arange(T) * 0.01, {"pots": make_stream(["p1"], np.ones((T, 1))),
                                    "markers": make_stream(["m1", "m2"], markers)}, robot="diego", rate_hz=100.0)
    save_log(log, tmp_path / "run.csv")
    back = import_log([tmp_path / "run.csv"]).log
    np.testing.assert_array_equal(back.time, log.time)
    np.testing.assert_array_equal(back.streams["markers"].data, markers)
    np.testing.assert_array_equal(back.streams["pots"].data, log.streams["pots"].data)


def test_lab_table_with_units_names_and_marker_triplets(tmp_path):
    t_ms = np.arange(10) * 20.0  # 50 Hz in ms
    rows = [[tm, 90.0, -45.0, 1000.0, 2000.0, 3000.0, "ok"] for tm in t_ms]
    path = _csv(tmp_path / "lab.csv", ["stamp_ms", "ELB deg", "SHO deg", "M1_x", "M1_y", "M1_z", "status"], rows)
    mapping = parse_map({
        "sources": {"lab": {"file": "lab.csv", "time": "stamp_ms", "time_unit": "ms"}},
        "streams": {"q": {"columns": {"SHO deg": "shoulder", "ELB deg": "elbow"}, "unit": "deg"},
                    "markers": {"columns": {"M1": "hand"}, "unit": "mm"}}})
    log = import_log([path], mapping).log
    np.testing.assert_allclose(log.time, t_ms / 1000)
    np.testing.assert_allclose(log.streams["q"].data[0], [-np.pi / 4, np.pi / 2])
    assert log.streams["markers"].names == ("hand",)
    np.testing.assert_allclose(log.streams["markers"].data[0, 0], [1.0, 2.0, 3.0])
    assert log.rate_hz == 50.0


@pytest.mark.parametrize("streams, error, message", [
    ({"q": {"columns": {"SHO dg": "shoulder"}}}, MapError, "no column 'SHO dg' .* did you mean 'SHO deg'"),
    ({"q": {"columns": {"SHO deg": "shoulder"}, "unit": "degree/s"}}, UnitError, "unknown unit 'degree/s'"),
    ({"q": {"columns": {"status": "shoulder"}}}, MapError, "no column 'status'"),  # text column
    ({"markers": {"columns": ["SHO deg"], "unit": "mm"}}, MapError, "a single number, a marker needs x, y, z"),
    ({"markers": {"columns": ["M1"]}}, MapError, "states no unit for marker 'M1'"),
    ({"tau": {"columns": {"SHO deg": "shoulder"}, "unit": "A"}}, MapError, "give `torque_constant`"),
    ({"tau": {"columns": {"SHO deg": "shoulder"}, "side": "motor"}}, MapError, "needs `transmission: ratio:`"),
])
def test_bad_mappings_of_a_table_are_one_line_errors(tmp_path, streams, error, message):
    rows = [[k * 0.1, 1.0, 2.0, 3.0, 4.0, "ok"] for k in range(5)]
    path = _csv(tmp_path / "lab.csv", ["time", "SHO deg", "M1_x", "M1_y", "M1_z", "status"], rows)
    with pytest.raises(error, match=message) as err:
        import_log([path], parse_map({"streams": streams}))
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("text, error, message", [
    ("t,a\n0,1\n1,2\n", MapError, "no 'time' column \\(columns: t, a\\); name the time column with `time:`"),
    ("time,a\n0,1\n-1,2\n", LogFormatError, "time goes back at row 2 \\(0.0 then -1.0\\)"),
    ("time,a\n1700000000.000000001,1\n1699999999.99,2\n", LogFormatError, "\\(1700000000.0 then 1699999999.99\\)"),
    ("time,a\n", LogFormatError, "header but no rows"),
    ("time,a,a\n0,1,2\n", LogFormatError, "duplicate column 'a'"),
    ("time,q.j1\nx,1\n", LogFormatError, "non-numeric"),
])
def test_bad_csv_files_are_one_line_errors(tmp_path, text, error, message):
    (tmp_path / "x.csv").write_text(text)
    with pytest.raises(error, match=message):
        import_log([tmp_path / "x.csv"])


def test_missing_and_unknown_files(tmp_path):
    with pytest.raises(InputFileError, match="no such file"):
        import_log([tmp_path / "nope.csv"])
    (tmp_path / "x.xlsx").write_text("")
    with pytest.raises(InputFileError, match="unknown source format"):
        import_log([tmp_path / "x.xlsx"])
    (tmp_path / "a.csv").write_text("time,q.j\n0,1\n1,2\n")
    mapping = parse_map({"sources": {"pos": {"file": "pos_*.csv"}}})
    with pytest.raises(MapError, match="a.csv matches no source in the map"):
        import_log([tmp_path / "a.csv"], mapping)
    mapping = parse_map({"sources": {"a": {"file": "a.csv"}, "b": {"file": "b.csv"}}})
    with pytest.raises(MapError, match="source 'b' .* matches none of the files given"):
        import_log([tmp_path / "a.csv"], mapping)


def _two_rates(tmp_path):
    """q at 100 Hz from 0 s, tau at 1 kHz from 0.0105 s: straight lines, so interpolation is exact."""
    t1 = np.arange(0, 100) * 0.01
    t2 = 0.0105 + np.arange(0, 900) * 0.001
    a = _csv(tmp_path / "a.csv", ["time", "q.j"], [[t, 2 * t + 1] for t in t1])
    b = _csv(tmp_path / "b.csv", ["time", "tau.j"], [[t, -3 * t] for t in t2])
    return a, b


def test_streams_at_different_rates_need_a_clock_and_meet_on_it(tmp_path):
    a, b = _two_rates(tmp_path)
    with pytest.raises(MapError, match=r"different clocks \(q ~100 Hz, tau ~1000 Hz\).*--rate"):
        import_log([a, b])
    result = import_log([a, b], rate_hz=50.0)
    log = result.log
    assert log.time[0] == pytest.approx(0.0105) and log.time[-1] <= 0.99 and log.rate_hz == 50.0
    np.testing.assert_allclose(np.diff(log.time), 0.02)
    np.testing.assert_allclose(log.streams["q"].column("j"), 2 * log.time + 1, atol=1e-12)
    np.testing.assert_allclose(log.streams["tau"].column("j"), -3 * log.time, atol=1e-12)
    assert "span every stream covers" in result.clock
    on_a = import_log([a, b], parse_map({"clock": {"source": "b"}, "interpolation": "previous"})).log
    assert on_a.n_samples == np.count_nonzero((0.0105 + np.arange(900) * 0.001) <= 0.99 + 1e-12)


def test_one_clock_written_in_milliseconds_and_in_seconds_is_one_clock(tmp_path):
    """Two files of one 100-Hz clock, one stamped in ms: after the conversion their stamps differ by
    rounding only, and they meet on that clock without --rate."""
    t = np.arange(300) * 0.01
    a = _csv(tmp_path / "a.csv", ["t", "q.j"], [[round(1000 * x, 3), x] for x in t])
    b = _csv(tmp_path / "b.csv", ["time", "tau.j"], [[x, -x] for x in t])
    mapping = parse_map({"sources": {"a": {"file": "a.csv", "time": "t", "time_unit": "ms"}, "b": {"file": "b.csv"}}})
    log = import_log([a, b], mapping).log
    assert log.n_samples == 300
    np.testing.assert_allclose(log.streams["q"].column("j"), t, atol=1e-9)
    np.testing.assert_allclose(log.streams["tau"].column("j"), -t, atol=1e-9)
    (tmp_path / "c.csv").write_text("time,tau.j\n" + "".join(f"{x + 0.003},{-x}\n" for x in t))
    with pytest.raises(MapError, match="different clocks"):  # 3 ms apart: another clock
        import_log([a, tmp_path / "c.csv"], parse_map({"sources": {"a": {"file": "a.csv", "time": "t",
                                                                         "time_unit": "ms"}, "c": {"file": "c.csv"}}}))


def test_a_gap_is_not_bridged_unless_the_map_allows_it(tmp_path):
    t = np.concatenate([np.arange(50) * 0.01, 1.5 + np.arange(50) * 0.01])  # 1 s without a sample
    path = _csv(tmp_path / "g.csv", ["time", "q.j"], [[x, x] for x in t])
    with pytest.raises(LogFormatError, match=r"no sample for 1.01 s after t = 0.49 s, longer than max_gap_s = 0.1"):
        import_log([path], rate_hz=100.0)
    log = import_log([path], parse_map({"sources": {"g": {"max_gap_s": 2.0}}, "clock": {"rate_hz": 100}})).log
    np.testing.assert_allclose(log.streams["q"].column("j"), log.time, atol=1e-12)


def test_current_through_torque_constant_and_ratio(tmp_path):
    path = _csv(tmp_path / "m.csv", ["time", "i1", "i2"], [[0.0, 100.0, -50.0], [0.1, 200.0, 0.0]])
    mapping = parse_map({"transmission": {"ratio": [10, 20]},
                         "streams": {"tau": {"columns": {"i1": "j1", "i2": "j2"}, "unit": "mA", "side": "motor",
                                             "torque_constant": {"j1": 0.5, "j2": 0.25}}}})
    tau = import_log([path], mapping).log.streams["tau"].data
    np.testing.assert_allclose(tau, [[10 * 0.5 * 0.1, 20 * 0.25 * -0.05], [10 * 0.5 * 0.2, 0.0]])


def test_derived_velocities_and_window(tmp_path):
    t = np.arange(0, 10, 0.005)  # 200 Hz
    q = np.sin(np.pi * t) * (t > 3)  # still for 3 s, then moves
    path = _csv(tmp_path / "s.csv", ["time", "q.j"], np.column_stack([t, q]))
    mapping = parse_map({"filter": {"cutoff_hz": 10}, "derive": ["qd", "qdd"], "window": "auto"})
    log = import_log([path], mapping).log
    # the motion starts at 3 s; the window keeps 0.25 s before it, and the filter spreads it a little
    assert 2.4 < log.time[0] < 3.0 and log.time[-1] == pytest.approx(t[-1])
    inner = (log.time > 4) & (log.time < 9)
    np.testing.assert_allclose(log.streams["qd"].column("j")[inner], np.pi * np.cos(np.pi * log.time[inner]),
                               atol=0.02)
    cut = import_log([path], parse_map({"window": [2.0, 4.0]})).log
    assert cut.time[0] == 2.0 and cut.time[-1] < 4.0 and list(cut.streams) == ["q"]
    with pytest.raises(MapError, match="window: auto finds the motion from qd"):
        import_log([path], parse_map({"window": "auto"}))
    with pytest.raises(LogFormatError, match="cut-off 150 Hz must be below half the sample rate"):
        import_log([path], parse_map({"filter": {"cutoff_hz": 150}}))


def test_a_misspelt_stream_column_gets_a_close_match(tmp_path):
    # the case: `tua.joint2` used to become a stream `tua` and the joint silently lost its torque
    (tmp_path / "x.csv").write_text("time,q.joint1,q.joint2,tau.joint1,tua.joint2\n0,1,2,3,4\n1,2,3,4,5\n")
    with pytest.raises(MapError, match=r"column 'tua.joint2' names no stream \('tua'\) — did you mean 'tau'\?"):
        import_log([tmp_path / "x.csv"])


def test_pots_in_millivolts_are_brought_to_volts(tmp_path):
    # the case: `unit: mV` in a map left one pot in mV beside the others in V
    path = _csv(tmp_path / "amp.csv", ["time", "elbow", "knee", "count"], [[k * 0.01, 1.5, 1500.0, 7.0]
                                                                           for k in range(5)])
    mapping = parse_map({"streams": {"pots": {"columns": ["elbow", "knee", "count"],
                                              "unit": {"knee": "mV", "count": "counts", "*": "V"}}}})
    result = import_log([path], mapping)
    np.testing.assert_allclose(result.log.streams["pots"].data, [[1.5, 1.5, 7.0]] * 5)  # counts stay counts
    assert result.streams[0][3] == "V/mV/counts -> V/counts"


def test_lab_csv_quirks_semicolons_header_units_and_repeated_stamps(tmp_path):
    # a user trial's files: a European export (semicolons, decimal commas), units in the headers
    # (`[mV]`, which the map then need not repeat), a time stamp a logger wrote twice
    path = tmp_path / "amp.csv"
    path.write_text("t [s];elbow [mV];knee [mV]\n0;1500,5;200\n0,01;1501;201\n0,01;1502;202\n0,02;1503;203\n")
    mapping = parse_map({"streams": {"pots": {"columns": ["elbow [mV]", "knee [mV]"]}},
                         "sources": {"amp": {"file": "amp.csv", "time": "t [s]"}}})
    result = import_log([path], mapping)
    np.testing.assert_allclose(result.log.time, [0.0, 0.01, 0.02])
    np.testing.assert_allclose(result.log.streams["pots"].data, [[1.5005, 0.2], [1.501, 0.201], [1.503, 0.203]])
    assert any("1 repeated time stamps dropped (first kept)" in n for n in result.notes)
    assert result.streams[0][3] == "mV -> V"


def test_lowercase_millivolts_are_millivolts(tmp_path):
    path = _csv(tmp_path / "amp.csv", ["time", "elbow"], [[k * 0.01, 1500.0] for k in range(5)])
    mapping = parse_map({"streams": {"pots": {"columns": ["elbow"], "unit": "mv"}}})
    np.testing.assert_allclose(import_log([path], mapping).log.streams["pots"].data, 1.5)


def test_a_header_unit_is_taken_only_where_the_map_leaves_it_and_it_fits(tmp_path):
    # a review: `knee (A)` is a label, not amperes; a map's scale rules over a header's [deg];
    # a first row of integers still leaves decimal commas to the rows after it; `[mv]` is mV
    path = tmp_path / "lab.csv"
    path.write_text("time,knee (A),knee (B),q1 [deg],pot [mv]\n0,1,2,90,1500\n0.1,1,2,90,1500\n")
    mapping = parse_map({"streams": {"q": {"columns": {"knee (A)": "j1", "knee (B)": "j2", "q1 [deg]": "j3"},
                                           "scale": {"j3": 0.0174533, "*": 1.0}},
                                     "pots": {"columns": {"pot [mv]": "p"}}}})
    log = import_log([path], mapping).log
    np.testing.assert_allclose(log.streams["q"].data[0], [1.0, 2.0, 90 * 0.0174533])
    np.testing.assert_allclose(log.streams["pots"].data[:, 0], 1.5)
    (tmp_path / "semi.csv").write_text("t;elbow\n0;1500\n0,01;1501,5\n0,02;1502\n")
    mapping = parse_map({"sources": {"s": {"file": "semi.csv", "time": "t"}},
                         "streams": {"pots": {"columns": ["elbow"]}}})
    np.testing.assert_allclose(import_log([tmp_path / "semi.csv"], mapping).log.streams["pots"].data[:, 0],
                               [1500, 1501.5, 1502])
