"""Log I/O: HDF5 and CSV carry the same content; validation gives one clear error per bad input."""

import h5py
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from diegocal.errors import InputFileError, LogFormatError, MissingStreamError
from diegocal.io import Log, Stream, Truth, load_log, make_stream, save_log

NAME = st.text(alphabet="abcdefghijklmnopqrstuvwxyz_0123456789.", min_size=1, max_size=8).filter(
    lambda s: not s.startswith(".") and not s.endswith(".") and not s.endswith((".x", ".y", ".z"))
)
FINITE = st.floats(-1e6, 1e6, allow_nan=False, allow_infinity=False)


@st.composite
def logs(draw):
    T = draw(st.integers(1, 12))
    steps = draw(arrays(np.float64, T, elements=st.floats(1e-3, 10.0)))
    time = np.cumsum(steps) - steps[0] + draw(st.floats(-100, 100))
    time = np.unique(time)
    if time.shape[0] != T:  # rounding merged two samples: keep it simple, rebuild evenly
        time = np.arange(T) * 0.01
    streams = {}
    for stream in draw(st.lists(st.sampled_from(["pots", "q", "tau", "pressure", "valve"]), unique=True, max_size=3)):
        names = draw(st.lists(NAME, min_size=1, max_size=4, unique=True))
        streams[stream] = make_stream(names, draw(arrays(np.float64, (T, len(names)), elements=FINITE)))
    if draw(st.booleans()):
        names = draw(st.lists(NAME, min_size=1, max_size=3, unique=True))
        data = draw(arrays(np.float64, (T, len(names), 3), elements=FINITE | st.just(np.nan)))
        streams["markers"] = make_stream(names, data)
    robot = draw(st.none() | st.sampled_from(["diego", "arm3"]))
    rate = draw(st.none() | st.floats(1.0, 5000.0))
    return Log(time=time, streams=streams, robot=robot, rate_hz=rate)


def assert_same(a: Log, b: Log) -> None:
    np.testing.assert_array_equal(a.time, b.time)
    assert set(a.streams) == set(b.streams)
    for k in a.streams:
        assert a.streams[k].names == b.streams[k].names
        np.testing.assert_array_equal(a.streams[k].data, b.streams[k].data)
    assert a.robot == b.robot
    assert a.rate_hz == b.rate_hz


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(log=logs(), suffix=st.sampled_from([".h5", ".csv"]))
def test_round_trip_is_exact(tmp_path, log, suffix):
    path = tmp_path / f"log{suffix}"
    save_log(log, path)
    assert_same(log, load_log(path))


@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(log=logs())
def test_hdf5_and_csv_hold_the_same_content(tmp_path, log):
    save_log(log, tmp_path / "a.h5")
    save_log(load_log(tmp_path / "a.h5"), tmp_path / "a.csv")
    assert_same(load_log(tmp_path / "a.h5"), load_log(tmp_path / "a.csv"))


def test_truth_round_trips_in_hdf5(tmp_path):
    truth = Truth(
        params={"pots": {"p": {"gain": 1.2, "bias": 0.1}}},
        effects=[{"cause": "backlash", "channel": "p", "values": {"width": 0.02}}],
        signals={"q": make_stream(["j1"], np.arange(3.0)[:, None])},
    )
    log = Log(np.arange(3) * 0.1, {"pots": make_stream(["p"], np.ones((3, 1)))}, truth=truth)
    save_log(log, tmp_path / "t.h5")
    back = load_log(tmp_path / "t.h5")
    assert back.truth.params == truth.params
    assert back.truth.effects == truth.effects
    np.testing.assert_array_equal(back.truth.signals["q"].data, truth.signals["q"].data)
    with h5py.File(tmp_path / "t.h5") as f:  # DESIGN.md: /truth with attributes params, effects
        assert "params" in f["truth"].attrs and "effects" in f["truth"].attrs


def good_log(T=4):
    return Log(np.arange(T) * 0.01, {"pots": make_stream(["a", "b"], np.zeros((T, 2)))})


@pytest.mark.parametrize(
    "build, message",
    [
        (lambda: Log(np.array([0.0, 0.2, 0.1]), {}), "not strictly increasing"),
        (lambda: Log(np.array([0.0, np.nan, 0.1]), {}), "NaN"),
        (lambda: Log(np.arange(3.0), {"pots": Stream(("a",), np.zeros((4, 1)))}), "expected data of shape (3, 1)"),
        (lambda: Log(np.arange(3.0), {"pots": make_stream(["a", "a"], np.zeros((3, 2)))}), "duplicate channel names"),
        (
            lambda: Log(np.arange(3.0), {"pots": make_stream(["a"], [[0.0], [np.nan], [1.0]])}),
            "NaN or infinite value at sample 1",
        ),
        (
            lambda: Log(np.arange(3.0), {"markers": make_stream(["m"], np.zeros((3, 1, 4)))}),
            "expected data of shape (3, 1, 3)",
        ),
        (lambda: Log(np.array([]), {}), "no samples"),
    ],
)
def test_invalid_logs_raise_one_clear_error(build, message):
    with pytest.raises(LogFormatError, match=message.replace("(", r"\(").replace(")", r"\)")):
        build()


def test_markers_may_be_nan():
    data = np.zeros((3, 1, 3))
    data[1] = np.nan
    Log(np.arange(3.0), {"markers": make_stream(["m"], data)})


def test_missing_file(tmp_path):
    with pytest.raises(InputFileError, match="no such file"):
        load_log(tmp_path / "nope.h5")


def test_not_hdf5_or_csv(tmp_path):
    path = tmp_path / "log.txt"
    path.write_text("hello")
    with pytest.raises(LogFormatError, match="expected an HDF5 .h5 or a .csv"):
        load_log(path)


@pytest.mark.parametrize("where", ["index", "data"])
def test_a_damaged_hdf5_log_is_one_error_that_names_the_file(tmp_path, where):
    """A file whose header opens but whose bytes were overwritten (a failed copy, a bad disk) fails
    where they are read, its index or a compressed stream's data: the error names the file."""
    rng = np.random.default_rng(0)
    log = Log(time=np.arange(20000) * 0.01, streams={"tau": make_stream(["a", "b"], rng.normal(size=(20000, 2)))})
    path = tmp_path / "a.h5"
    save_log(log, path)
    size = path.stat().st_size
    with h5py.File(path, "r") as f:  # a chunk of the stream's data, or a third of the file (its B-tree)
        at, n = (f["tau/data"].id.get_chunk_info(0).byte_offset, 2000) if where == "data" else (size // 3, size // 3)
    with open(path, "r+b") as fh:
        fh.seek(at)
        fh.write(rng.bytes(n))
    with pytest.raises(LogFormatError, match=r"a\.h5: damaged HDF5 file, it cannot be read \(.+\)"):
        load_log(path)


def test_wrong_format_and_version(tmp_path):
    save_log(good_log(), tmp_path / "a.h5")
    with h5py.File(tmp_path / "a.h5", "a") as f:
        f.attrs["version"] = 7
    with pytest.raises(LogFormatError, match="version 7"):
        load_log(tmp_path / "a.h5")
    with h5py.File(tmp_path / "a.h5", "a") as f:
        f.attrs["format"] = "something-else"
    with pytest.raises(LogFormatError, match="format attribute"):
        load_log(tmp_path / "a.h5")
    (tmp_path / "b.csv").write_text("# diegocal-log version=2\ntime,pots.a\n0,1\n")
    with pytest.raises(LogFormatError, match="version 2"):
        load_log(tmp_path / "b.csv")


def test_source_round_trips_and_a_broken_one_is_one_error(tmp_path):
    from dataclasses import replace

    source = {"command": "diegocal predict m.sgp held.h5", "model": "/x/m.sgp", "log": "/x/held.h5"}
    save_log(replace(good_log(), source=source), tmp_path / "p.h5")
    assert load_log(tmp_path / "p.h5").source == source
    np.testing.assert_array_equal(load_log(tmp_path / "p.h5").time, good_log().time)
    with h5py.File(tmp_path / "p.h5", "a") as f:
        f.attrs["source"] = "{unclosed: [1, 2"
    with pytest.raises(LogFormatError, match="'source' attribute is not YAML"):
        load_log(tmp_path / "p.h5")


def test_csv_duplicates_and_bad_columns(tmp_path):
    (tmp_path / "d.csv").write_text("time,pots.a,pots.a\n0,1,2\n")
    with pytest.raises(LogFormatError, match="duplicate column 'pots.a'"):
        load_log(tmp_path / "d.csv")
    (tmp_path / "n.csv").write_text("time,pots.a\n0,1\n1,x\n")
    with pytest.raises(LogFormatError, match="non-numeric"):
        load_log(tmp_path / "n.csv")
    (tmp_path / "t.csv").write_text("time,pots.a\n0,1\n0,2\n")
    with pytest.raises(LogFormatError, match="not strictly increasing"):
        load_log(tmp_path / "t.csv")
    (tmp_path / "c.csv").write_text("pots.a\n1\n")
    with pytest.raises(LogFormatError, match="no 'time' column"):
        load_log(tmp_path / "c.csv")
    (tmp_path / "cut.csv").write_text("time,pots.a,pots.b\n0,1,2\n0.01,1.5")  # a copy cut off mid-row
    with pytest.raises(LogFormatError, match="last row has 2 of 3 fields: the file looks cut short"):
        load_log(tmp_path / "cut.csv")


def test_nan_in_stream_that_forbids_it_is_reported_with_file(tmp_path):
    (tmp_path / "n.csv").write_text("time,tau.j1\n0,1\n1,nan\n")
    with pytest.raises(LogFormatError, match=r"n\.csv: stream 'tau': NaN"):
        load_log(tmp_path / "n.csv")


def test_missing_stream_names_the_command():
    with pytest.raises(MissingStreamError, match="log has no 'markers' stream \\(needed by stac\\); it has: pots"):
        good_log().stream("markers", needed_by="stac")
    joints = Log(np.arange(3) * 0.1, {k: make_stream(["j"], np.ones((3, 1))) for k in ("q", "qd", "tau")})
    with pytest.raises(MissingStreamError, match=r"no 'qdd' stream.*derives it from q \(`derive: \[qdd\]`"):
        joints.stream("qdd", needed_by="sgp-fit")  # a bag's joint states (a user trial: "did you mean 'qd'?")


def test_failed_write_leaves_no_file(tmp_path, monkeypatch):
    import diegocal.io.files as files

    def broken(log, path):
        path.write_text("half")
        raise RuntimeError("disk full")

    monkeypatch.setattr(files, "_save_h5", broken)
    with pytest.raises(RuntimeError):
        save_log(good_log(), tmp_path / "out.h5")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("suffix", [".h5", ".csv"])
def test_log_robot_reads_the_header_only(tmp_path, suffix):
    from diegocal.io.files import log_robot

    log = Log(np.arange(3) * 0.1, {"pots": make_stream(["p"], np.ones((3, 1)))}, robot="arm3")
    save_log(log, tmp_path / f"a{suffix}")
    assert log_robot(tmp_path / f"a{suffix}") == "arm3"
    save_log(good_log(), tmp_path / f"b{suffix}")
    assert log_robot(tmp_path / f"b{suffix}") is None


@pytest.mark.parametrize("robot", ["/labs/my robot", "C:\\robots\\arm", "it's/arm", "arm3"])
def test_a_csv_logs_robot_path_with_spaces_or_quotes_reads_back(tmp_path, robot):
    # a user trial: a robot folder named "my robot" was read back as "/labs/my"
    from diegocal.io.files import log_robot

    log = Log(np.arange(3) * 0.1, {"pots": make_stream(["p"], np.ones((3, 1)))}, robot=robot)
    save_log(log, tmp_path / "a.csv")
    assert log_robot(tmp_path / "a.csv") == robot
    assert load_log(tmp_path / "a.csv").robot == robot


def test_an_older_csv_logs_unquoted_robot_path_reads_as_written():
    from diegocal.io.files import CSV_HEADER_PREFIX, header_fields

    line = f"{CSV_HEADER_PREFIX} version=1 robot=/data/o'neil's/arm3 rate_hz=100.0"
    assert header_fields(line) == {"version": "1", "robot": "/data/o'neil's/arm3", "rate_hz": "100.0"}


def test_damaged_bytes_anywhere_give_one_error_that_names_the_file(tmp_path):
    """Seeded damage at random places of a small log (object headers, B-trees, chunks, data): reading
    it, or listing its streams as batch does, fails with the library's error naming the file, never
    with h5py's own exception (KeyError, RuntimeError, ...)."""
    from diegocal.errors import DiegocalError
    from diegocal.io.files import log_streams

    rng = np.random.default_rng(1)
    log = Log(time=np.arange(3000) * 0.01, streams={"tau": make_stream(["a", "b"], rng.normal(size=(3000, 2)))})
    save_log(log, tmp_path / "good.h5")
    data = (tmp_path / "good.h5").read_bytes()
    for _ in range(60):
        at, n = int(rng.integers(0, len(data) - 64)), int(rng.integers(1, 64))
        (tmp_path / "bad.h5").write_bytes(data[:at] + rng.bytes(n) + data[at + n :])
        for read in (load_log, log_streams):
            try:
                read(tmp_path / "bad.h5")
            except DiegocalError as exc:
                assert "bad.h5" in str(exc), (at, n, str(exc))


def test_a_missing_channel_names_the_stream_it_is_missing_from():
    """A user's `joint1` against a log of j1.. read "no channel 'joint1' in stream": which one?"""
    from diegocal.errors import UnknownNameError

    log = Log(time=np.arange(3) * 0.01, streams={"tau": make_stream(["j1", "j2"], np.zeros((3, 2)))})
    with pytest.raises(UnknownNameError, match="no channel 'joint1' in the log's 'tau' stream \\(has j1, j2\\)"):
        log.stream("tau").select(["joint1"])


def test_a_truncated_hdf5_log_is_one_error_line_wherever_it_is_read(tmp_path):
    """A user trial's `predict MODEL trunc.h5` printed h5py's message without the file's name: the
    header reader (the robot the log names) says what load_log says."""
    from diegocal.io.files import log_robot

    save_log(good_log(200), tmp_path / "g.h5")
    data = (tmp_path / "g.h5").read_bytes()
    (tmp_path / "cut.h5").write_bytes(data[: len(data) // 2])
    for read in (load_log, log_robot):
        with pytest.raises(LogFormatError, match=r"cut.h5: cannot read HDF5 file \("):
            read(tmp_path / "cut.h5")
