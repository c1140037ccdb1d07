"""`diegocal import` of the marker formats labs export (TRC, Vicon Nexus CSV, OptiTrack Motive CSV),
written here by hand as the vendors write them: each import gives a log `diegocal stac` calibrates
as it does the simulated session itself."""

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from diegocal.cli import app
from diegocal.cli.testing import one_line_error
from diegocal.errors import LogFormatError
from diegocal.io import Log, load_log, make_stream, save_log
from diegocal.io.importers import MapError, import_log, parse_map
from tests.io.labfiles import fitted_values, run_ok, write_motive_csv, write_trc, write_vicon_csv

runner = CliRunner()


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    """10 s of the finger (markers at 50 Hz, pots at 100 Hz) and STAC's pot gains on it as simulated."""
    folder = tmp_path_factory.mktemp("finger")
    run_ok(["simulate", "kinematics", "--robot", "finger", "--duration", "10", "--seed", "1", "-o",
         folder / "sim.h5", "-q"])
    sim = load_log(folder / "sim.h5")
    direct = Log(sim.time[::2], {k: make_stream(s.names, s.data[::2]) for k, s in sim.streams.items()},
                 robot="finger", rate_hz=50.0)
    save_log(direct, folder / "direct.h5")
    run_ok(["stac", folder / "direct.h5", "-o", folder / "direct.calib.yaml", "-q"])
    return sim, fitted_values(folder / "direct.calib.yaml")


def _pots_csv(path, sim):
    pots = sim.streams["pots"]
    np.savetxt(path, np.column_stack([sim.time, pots.data]), delimiter=",", header="time," + ",".join(pots.names),
               comments="", fmt="%.17g")
    return path


def _calibrates_like_the_simulation(tmp_path, session, files, mapping):
    sim, want = session
    (tmp_path / "map.yaml").write_text(yaml.safe_dump({"robot": "finger", **mapping}, sort_keys=False))
    run_ok(["import", *files, "--map", tmp_path / "map.yaml", "-o", tmp_path / "imported.h5", "-q"])
    log = load_log(tmp_path / "imported.h5")
    markers = sim.streams["markers"]
    assert log.streams["markers"].names == markers.names
    np.testing.assert_allclose(log.time, sim.time[::2], atol=1e-9)
    np.testing.assert_allclose(log.streams["markers"].data, markers.data[::2], atol=2e-6)
    assert np.array_equal(np.isnan(log.streams["markers"].data), np.isnan(markers.data[::2]))
    run_ok(["stac", tmp_path / "imported.h5", "-o", tmp_path / "imported.calib.yaml", "-q"])
    got = fitted_values(tmp_path / "imported.calib.yaml")
    assert got.keys() == want.keys()
    for key, value in want.items():
        assert got[key] == pytest.approx(value, rel=1e-3, abs=1e-6), key
    return log


@pytest.mark.parametrize("unit, scale", [("mm", 1000.0), ("m", 1.0)])
def test_trc_with_a_pot_table(tmp_path, session, unit, scale):
    sim, _ = session
    markers = sim.streams["markers"]
    trc = write_trc(tmp_path / "walk.trc", markers.names, markers.data[::2] * scale, rate=50.0, unit=unit)
    pots = _pots_csv(tmp_path / "pots.csv", sim)
    _calibrates_like_the_simulation(tmp_path, session, [trc, pots], {
        "sources": {"mocap": "walk.trc", "amp": "pots.csv"},
        "streams": {"markers": {"source": "mocap"},
                    "pots": {"source": "amp", "columns": list(sim.streams["pots"].names), "unit": "V"}}})


def test_vicon_nexus_csv_with_devices_and_subject_prefixes(tmp_path, session):
    sim, _ = session
    markers, pots = sim.streams["markers"], sim.streams["pots"]
    path = write_vicon_csv(tmp_path / "trial01.csv", [f"finger:{n}" for n in markers.names], markers.data[::2] * 1000,
                           rate=50.0, devices=("Pots - Voltage", list(pots.names), pots.data, "V"))
    log = _calibrates_like_the_simulation(tmp_path, session, [path], {
        "streams": {"markers": {}, "pots": {"table": "devices",
                                            "columns": {f"Pots - Voltage.{n}": n for n in pots.names}}}})
    np.testing.assert_allclose(log.streams["pots"].data, pots.data[::2], atol=1e-6)  # sub frame 0 of each frame


def test_motive_csv_markers_beside_a_rigid_body(tmp_path, session):
    sim, _ = session
    markers = sim.streams["markers"]
    labelled = markers.data[::2]
    path = write_motive_csv(tmp_path / "take.csv", [f"finger:{n}" for n in markers.names], labelled, rate=50.0,
                            unit="Meters", body=("palm", np.nanmean(labelled, axis=1)))
    pots = _pots_csv(tmp_path / "pots.csv", sim)
    _calibrates_like_the_simulation(tmp_path, session, [path, pots], {
        "sources": {"mocap": "take.csv", "amp": "pots.csv"},
        "streams": {"markers": {"source": "mocap"},
                    "pots": {"source": "amp", "columns": list(sim.streams["pots"].names), "unit": "V"}}})
    result = import_log([path])
    assert result.log.streams["markers"].names == markers.names  # the unlabelled marker left out
    assert any("rigid_bodies, rigid_body_markers not imported" in n for n in result.notes)
    body = import_log([path], parse_map({"streams": {"markers": {"table": "rigid_bodies"}}})).log
    assert body.streams["markers"].names == ("palm",)


def test_subjects_unknown_names_and_close_matches(tmp_path, caplog):
    xyz = np.random.default_rng(2).normal(size=(20, 3, 3)) * 100
    path = write_vicon_csv(tmp_path / "two.csv", ["finger:m1", "finger:m22", "wand:tip"], xyz, rate=100.0)
    result = import_log([path])
    assert result.log.streams["markers"].names == ("finger:m1", "finger:m22", "wand:tip")
    assert "subjects finger, wand kept in the names (pick one with `subject:`)" in result.streams[0][3]
    with caplog.at_level("WARNING", logger="diegocal"):
        log = import_log([path], parse_map({"robot": "finger", "streams": {"markers": {"subject": "finger"}}})).log
    assert log.streams["markers"].names == ("m1", "m22")
    np.testing.assert_allclose(log.streams["markers"].data[:, 1], xyz[:, 1] / 1000, atol=1e-9)
    assert any("1 marker(s) not in finger's sensors.yaml: m22 — did you mean 'm2'?" in r.getMessage()
               for r in caplog.records)
    with pytest.raises(MapError, match="no markers of subject 'fingr' .* did you mean 'finger'"):
        import_log([path], parse_map({"streams": {"markers": {"subject": "fingr"}}}))
    # mapped to the robot's names by their marker name alone
    mapped = import_log([path], parse_map({"streams": {"markers": {"columns": {"m22": "m2", "tip": "m5"}}}})).log
    assert mapped.streams["markers"].names == ("m2", "m5")
    chosen = import_log([path], parse_map({"streams": {"markers": {"subject": "finger", "columns": {"m22": "m2"}}}}))
    assert chosen.log.streams["markers"].names == ("m2",)


@pytest.mark.parametrize("name, text, message", [
    ("cut.trc", "PathFileType\t4\t(X/Y/Z)\tcut.trc\nDataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\n"
                "100\t100\t50\t1\tmm\nFrame#\tTime\tM\nX1\tY1\tZ1\n\n1\t0.0\t1\t2\t3\n2\t0.01\t1\t2\t3\n",
     r"cut.trc: truncated: NumFrames is 50, the file holds 2 frames"),
    ("bad.trc", "PathFileType\t4\t(X/Y/Z)\tbad.trc\nDataRate\tUnits\n100\tmm\nFrame#\tTime\tM\n\t\tX1\tY1\tZ1\n\n"
                "1\t0.0\t1\tx\t3\n",
     r"bad.trc: data row 1, column 4 holds 'x', not a number"),
    ("v.csv", "Trajectories\nfast\n,,M,,\nFrame,Sub Frame,X,Y,Z\n,,mm,mm,mm\n1,0,1,2,3\n",
     r"v.csv: Trajectories: the line after the section name should be its rate"),
    ("m.csv", "Format Version,1.23,Length Units,Inches\n\n,Type,Marker,Marker,Marker\n,Name,M,M,M\n"
              ",ID,1,1,1\n,,Position,Position,Position\nFrame,Time (Seconds),X,Y,Z\n0,0.0,1,2,3\n1,0.01,1,2,3\n",
     r"m.csv: Motive Length Units 'Inches'"),
])
def test_broken_mocap_files_are_one_line(tmp_path, name, text, message):
    (tmp_path / name).write_text(text)
    with pytest.raises(LogFormatError, match=message) as err:
        import_log([tmp_path / name])
    assert "\n" not in str(err.value)
    result = runner.invoke(app, ["import", str(tmp_path / name), "-o", str(tmp_path / "out.h5")])
    assert result.exit_code == 1 and message.split(": ", 1)[1][:20].replace("\\", "") in one_line_error(result)
    assert not (tmp_path / "out.h5").exists()
