"""Two files on two clocks: `diegocal import` estimates their offset from the motion both record,
warns when they disagree, and applies it with `time_offset: auto` (per file or per stream)."""

import numpy as np
import pytest

from diegocal.io import load_log
from diegocal.io.importers import MapError, import_log, parse_map
from diegocal.io.importers.clocks import estimate_offset, motion_speed
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
    a = motion_speed("q", t, np.cumsum(rng.normal(size=(2000, 2)), axis=0), 100.0)
    b = motion_speed("q", t, np.cumsum(rng.normal(size=(2000, 2)), axis=0), 100.0)
    assert estimate_offset(a, b) is None
    (tmp_path / "a.csv").write_text("time,q.j\n" + "".join(f"{x},{np.sin(x)}\n" for x in t))
    (tmp_path / "b.csv").write_text("time,pots.p\n" + "".join(f"{x},{v}\n" for x, v in zip(t, rng.normal(size=2000),
                                                                                          strict=True)))
    with pytest.raises(MapError, match="source 'b': time_offset: auto finds no motion shared with a.csv"):
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
