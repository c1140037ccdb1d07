"""Two files on two clocks: `diegocal import` estimates their offset from the motion both record,
warns when they disagree, and applies it with `time_offset: auto` (per file or per stream); where the
motion does not fix the offset (it repeats, or too little of it is shared) there is no estimate."""

import numpy as np
import pytest

from diegocal.io import load_log
from diegocal.io.importers import MapError, import_log, parse_map
from diegocal.io.importers.clocks import estimate_offset, motion_envelope
from tests.io.labfiles import run_ok, write_c3d

#: The pot logger started this long after the mocap (s): not a whole number of samples of either.
OFFSET = 3.517


@pytest.fixture(scope="module")
def two_clocks(tmp_path_factory):
    """The issue's case: 20 s of the finger; the mocap (100 Hz) records 0..16.5 s on its clock, the pot
    logger (100 Hz) 3.5..20 s on its own clock, which reads 0 at 3.517 s."""
    folder = tmp_path_factory.mktemp("clocks")
    run_ok(["simulate", "kinematics", "--robot", "finger", "--duration", "20", "--seed", "3", "-o", folder / "sim.h5",
            "-q"])
    sim = load_log(folder / "sim.h5")
    markers, pots = sim.streams["markers"], sim.streams["pots"]
    seen = sim.time <= 16.5 + 1e-9
    write_c3d(folder / "mocap.c3d", markers.names, markers.data[seen] * 1000.0, rate=100.0)
    logged = sim.time >= 3.5
    table = np.column_stack([sim.time[logged] - OFFSET, pots.data[logged]])
    np.savetxt(folder / "pots.csv", table, delimiter=",", header="time," + ",".join(pots.names), comments="",
               fmt="%.17g")
    return folder, sim


def _map(**source):
    return parse_map({"robot": "finger", "sources": {"mocap": "mocap.c3d", "amp": {"file": "pots.csv", **source}},
                      "streams": {"markers": {"source": "mocap"},
                                  "pots": {"source": "amp", "columns": ["fdp", "fds", "ext", "radial_int",
                                                                        "ulnar_int", "mcp_abd", "dip"]}}})


def test_the_offset_is_estimated_within_a_sample_and_named_in_a_warning(two_clocks, caplog):
    folder, _ = two_clocks
    with caplog.at_level("WARNING", logger="diegocal"):
        result = import_log([folder / "mocap.c3d", folder / "pots.csv"], _map())
    (est,) = result.offsets
    assert (est.reference, est.other) == ("mocap", "amp")
    assert est.offset_s == pytest.approx(OFFSET, abs=0.01) and est.r > 0.8
    (warning,) = [r.getMessage() for r in caplog.records if "clocks disagree" in r.getMessage()]
    assert warning.startswith("pots.csv and mocap.c3d: their clocks disagree by +3.5")
    assert "set `time_offset: 3.5" in warning and "for source 'amp'" in warning


@pytest.mark.parametrize("where", ["source", "stream"])
def test_an_offset_applied_gives_the_whole_overlap_aligned(two_clocks, caplog, where):
    folder, sim = two_clocks
    files = [folder / "mocap.c3d", folder / "pots.csv"]
    auto = import_log(files, _map(time_offset="auto"))
    assert any(n.startswith("time_offset: auto for amp: +3.51") for n in auto.notes)
    mapping = _map() if where == "stream" else _map(time_offset=OFFSET)
    if where == "stream":  # the offset stated on the pots stream, not on its file
        mapping = parse_map({**{"robot": "finger", "sources": {"mocap": "mocap.c3d", "amp": "pots.csv"}},
                             "streams": {"markers": {"source": "mocap"},
                                         "pots": {"source": "amp", "time_offset": OFFSET,
                                                  "columns": list(sim.streams["pots"].names)}}})
    with caplog.at_level("WARNING", logger="diegocal"):
        stated = import_log(files, mapping)
    assert not [r for r in caplog.records if "clocks disagree" in r.getMessage()]
    for log in (auto.log, stated.log):
        assert log.time[0] == pytest.approx(3.5, abs=0.011) and log.time[-1] == pytest.approx(16.5)  # 13 s, not 6
        k = np.searchsorted(sim.time, log.time)
        np.testing.assert_allclose(log.streams["pots"].data, sim.streams["pots"].data[k],
                                   atol=0.02 * np.ptp(sim.streams["pots"].data))


def test_files_without_a_shared_motion_give_no_estimate(tmp_path):
    rng = np.random.default_rng(0)
    t = np.arange(2000) * 0.01
    a = motion_envelope("q", t, np.cumsum(rng.normal(size=(2000, 2)), axis=0), 100.0)
    b = motion_envelope("q", t, np.cumsum(rng.normal(size=(2000, 2)), axis=0), 100.0)
    est = estimate_offset(a, b)
    assert not est.fixed and est.offset_s is None and est.why.startswith("no motion shared")
    (tmp_path / "a.csv").write_text("time,q.j\n" + "".join(f"{x},{np.sin(x)}\n" for x in t))
    (tmp_path / "b.csv").write_text("time,pots.p\n" + "".join(f"{x},{v}\n" for x, v in zip(t, rng.normal(size=2000),
                                                                                          strict=True)))
    with pytest.raises(MapError, match="source 'b': time_offset: auto: no motion shared .* state the offset in s"):
        import_log([tmp_path / "a.csv", tmp_path / "b.csv"],
                   parse_map({"sources": {"a": "a.csv", "b": {"file": "b.csv", "time_offset": "auto"}}}))


def test_the_cli_warns_and_shows_the_offset(two_clocks, tmp_path):
    folder, sim = two_clocks
    columns = ", ".join(sim.streams["pots"].names)
    (tmp_path / "map.yaml").write_text("sources: {mocap: mocap.c3d, amp: pots.csv}\nstreams:\n"
                                       f"  markers: {{source: mocap}}\n  pots: {{source: amp, columns: [{columns}]}}\n")
    out = run_ok(["import", folder / "mocap.c3d", folder / "pots.csv", "--map", tmp_path / "map.yaml",
                  "-o", tmp_path / "two.h5"]).output
    assert "warning: pots.csv and mocap.c3d: their clocks disagree by +3.5" in out
    assert "clock offset amp" in out


# ------------------------------------------------------------------ a slow, repeating motion (a user trial)
#: A planar 3R arm's links (m): markers on it move as its joints turn, pots read the joints.
LINKS = np.array([0.30, 0.25, 0.20])
#: The DAQ's clock reads 0 this long after the mocap's (s), as the map states.
DAQ_START = 2.345
#: One sample of the DAQ (s), the slower file and the one shifted.
DAQ_PERIOD = 0.02


def _arm_markers(q):
    """(T, 7, 3) m: a marker on the base and two on each link (its middle, its end) of the arm at joint
    angles q (T, 3) rad, in the plane z = 0.1 m."""
    step = LINKS[:, None] * np.stack([np.cos(np.cumsum(q, axis=1)), np.sin(np.cumsum(q, axis=1))], axis=-1)
    joints = np.concatenate([np.zeros((q.shape[0], 1, 2)), np.cumsum(step, axis=1)], axis=1)  # (T, 4, 2)
    xy = [np.broadcast_to([0.05, -0.05], (q.shape[0], 2))]
    for i in range(3):
        xy += [0.5 * (joints[:, i] + joints[:, i + 1]), joints[:, i + 1]]
    xy = np.stack(xy, axis=1)
    return np.concatenate([xy, np.full(xy.shape[:2] + (1,), 0.1)], axis=2)


def _sum_of_sines(rng, t):
    """(T, 3) rad: each joint a sum of four sines of 0.04-0.35 Hz, the trial's slow excitation."""
    f, phase, w = rng.uniform(0.04, 0.35, (3, 4)), rng.uniform(0, 2 * np.pi, (3, 4)), rng.uniform(0.5, 1.0, (3, 4))
    return 0.8 * ((w / w.sum(axis=1, keepdims=True)) * np.sin(2 * np.pi * f * t[:, None, None] + phase)).sum(axis=2)


def _wander(rng, t):
    """(T, 3) rad: Gaussian noise low-passed at 0.5 Hz, a motion that does not repeat."""
    from scipy.signal import butter, sosfiltfilt

    x = sosfiltfilt(butter(2, 0.5, fs=1.0 / (t[1] - t[0]), output="sos"), rng.standard_normal((t.size, 3)), axis=0)
    return 0.8 * x / x.std(axis=0)


def _two_clocks(folder, motion, seed, late=0.0):
    """40 s of the arm moving as ``motion`` says: the mocap (C3D, 100 Hz, mm, from 0 s) and the pots in a
    DAQ's CSV (50 Hz, mV, its own clock from 0 ms), which started ``late`` s after the DAQ_START the map
    states. Returns the map."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 50.0, 0.01)  # the arm's motion (s), longer than either file
    q = motion(rng, t)
    seen = t < 40.0
    xyz = _arm_markers(q[seen]) * 1000.0 + 0.5 * rng.standard_normal((int(seen.sum()), 7, 3))
    write_c3d(folder / "mocap.c3d", [f"m{i}" for i in range(7)], xyz, rate=100.0)
    daq = np.arange(0.0, 37.0, DAQ_PERIOD)  # the DAQ's clock (s)
    pots = np.column_stack([np.interp(daq + DAQ_START + late, t, q[:, j]) for j in range(3)])
    millivolts = 2500.0 + 1000.0 * pots + 2.0 * rng.standard_normal(pots.shape)
    np.savetxt(folder / "daq.csv", np.column_stack([daq * 1000.0, millivolts]), delimiter=",", fmt="%.3f",
               header="t_ms,p1,p2,p3", comments="")
    return {"sources": {"mocap": "mocap.c3d",
                        "daq": {"file": "daq.csv", "time": "t_ms", "time_unit": "ms", "time_offset": DAQ_START}},
            "streams": {"markers": {"source": "mocap"},
                        "pots": {"source": "daq", "columns": ["p1", "p2", "p3"], "unit": {"*": "mV"}}}}


def _auto(mapping):
    return {**mapping, "sources": {**mapping["sources"], "daq": {**mapping["sources"]["daq"], "time_offset": "auto"}}}


def _import(folder, mapping):
    return import_log([folder / "mocap.c3d", folder / "daq.csv"], parse_map(mapping))


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_a_repeating_motion_on_one_clock_gives_no_warning_and_no_wrong_offset(tmp_path, caplog, seed):
    """The trial's case: the map's offset is exact, the motion slow sums of sines. The peak of r alone
    was 25-29 s off on each of these seeds (r = 0.60-0.71), and its warning asked for it."""
    mapping = _two_clocks(tmp_path, _sum_of_sines, seed)
    with caplog.at_level("WARNING", logger="diegocal"):
        result = _import(tmp_path, mapping)
    assert not [r for r in caplog.records if "clocks disagree" in r.getMessage()]
    assert all(abs(e.offset_s) <= DAQ_PERIOD for e in result.offsets)
    assert len([n for n in result.notes if n.startswith("clocks of daq and mocap agree")]) == len(result.offsets)
    # where the motion does not fix the offset, the summary says the clocks were not checked
    unchecked = [n for n in result.notes if n.startswith("clocks of daq and mocap not checked: ")]
    assert len(unchecked) == 1 - len(result.offsets) and all(n.endswith("the stated clocks kept") for n in unchecked)
    assert result.log.time[-1] - result.log.time[0] == pytest.approx(37.0 - DAQ_PERIOD, abs=0.05)  # not cut


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_auto_on_a_repeating_motion_gives_the_offset_or_says_why(tmp_path, seed):
    """With `time_offset: auto` the same files give DAQ_START within a sample, or one line saying the
    motion does not fix it; never a shift of seconds (the peak of r alone moved the pots 25-29 s)."""
    try:
        result = _import(tmp_path, _auto(_two_clocks(tmp_path, _sum_of_sines, seed)))
    except MapError as e:
        assert str(e).startswith("source 'daq': time_offset: auto: ") and str(e).endswith("; state the offset in s")
        assert any(why in str(e) for why in ("the motion does not fix the offset (it repeats, or too little of it is "
                                             "shared)", "no motion shared", "the motion fixes the offset only to"))
        return
    (est,) = result.offsets
    assert est.offset_s == pytest.approx(DAQ_START, abs=DAQ_PERIOD)


def test_a_repeated_trajectory_is_not_fixed_by_its_peak():
    """A 20-s trajectory run three times: the shifts 20 s apart fit alike, so there is no estimate, and
    the reason names the other shift."""
    rng = np.random.default_rng(1)
    t = np.arange(0.0, 60.0, 0.05)
    once = np.convolve(rng.standard_normal(400 + 60), np.hanning(30), mode="same")[30:-30]  # 20 s at 20 Hz
    speed = np.abs(np.tile(once, 3))
    a = (t, speed + 0.05 * rng.standard_normal(t.size))
    late = t[:900]  # b: 45 s of the same runs, its clock 7.3 s behind
    b = (late, np.interp(late + 7.3, t, speed) + 0.05 * rng.standard_normal(late.size))
    est = estimate_offset(a, b)
    assert not est.fixed and est.why.startswith("the motion does not fix the offset (it repeats")
    assert est.r > 0.9 and est.rival_r > 0.9
    assert {round(est.best_s, 1), round(est.rival_s, 1)} <= {-12.7, 7.3, 27.3}


@pytest.mark.parametrize("seed", [0, 2, 3])
def test_an_offset_on_a_motion_that_does_not_repeat_is_found(tmp_path, caplog, seed):
    """The DAQ started 1.5 s later than the map says, the arm wandering: the check names +1.5 s within a
    sample, with its standard error, and `time_offset: auto` applies DAQ_START + 1.5 s."""
    mapping = _two_clocks(tmp_path, _wander, seed, late=1.5)
    with caplog.at_level("WARNING", logger="diegocal"):
        stated = _import(tmp_path, mapping)
    (est,) = stated.offsets
    assert est.offset_s == pytest.approx(1.5, abs=DAQ_PERIOD) and est.se_s < 2 * DAQ_PERIOD
    (warning,) = [r.getMessage() for r in caplog.records if "clocks disagree" in r.getMessage()]
    assert warning.startswith("daq.csv and mocap.c3d: their clocks disagree by +1.5") and "time_offset: 3.8" in warning
    auto = _import(tmp_path, _auto(mapping))
    assert auto.offsets[0].offset_s == pytest.approx(DAQ_START + 1.5, abs=DAQ_PERIOD)
    assert any(n.startswith("time_offset: auto for daq: +3.8") for n in auto.notes)


def test_too_short_an_overlap_gives_no_estimate():
    """6 s of the other file's motion against 40 s: no shift leaves enough independent samples."""
    rng = np.random.default_rng(4)
    t = np.arange(0.0, 40.0, 0.01)
    x = np.convolve(rng.standard_normal(t.size + 200), np.hanning(100), mode="same")[100:-100]
    short = t[:600]
    est = estimate_offset((t, x), (short, np.interp(short + 20.0, t, x)))
    assert not est.fixed and est.why.startswith("too little shared motion")
