"""`diegocal import` end to end: each format family gives a log that `stac` or `sgp-fit` accepts;
bad input is one line (exit 1), usage errors exit 2, and nothing half-written is left."""

import re
from pathlib import Path

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from diegocal.cli import app
from diegocal.cli.testing import one_line_error
from diegocal.io import Log, load_log, make_stream, save_log
from diegocal.io.importers import lowpass
from tests.io.labfiles import fitted_values, run_ok, write_bag, write_c3d, write_rostopic_csv

runner = CliRunner()
REAL_MAPS = Path(__file__).resolve().parents[2] / "sample_data" / "real"


@pytest.fixture(scope="module")
def arm3(tmp_path_factory):
    """10 s of the 3-link arm at 100 Hz (simulated: q, qd, qdd, tau with truth)."""
    path = tmp_path_factory.mktemp("arm3") / "arm3.h5"
    run_ok(["simulate", "dynamics", "--robot", "arm3", "--duration", "10", "--seed", "4", "-o", path, "-q"])
    return load_log(path)


def _fit_and_predict(log_path, tmp_path) -> np.ndarray:
    """sgp-fit --model pr on the imported log, predict it back: nMSE per joint."""
    run_ok(["sgp-fit", log_path, "--model", "pr", "-o", tmp_path / "fit.sgp", "-q"])
    run_ok(["predict", tmp_path / "fit.sgp", log_path, "-o", tmp_path / "pred.h5", "-q"])
    pred = load_log(tmp_path / "pred.h5")
    tau, measured = pred.streams["tau"].data, pred.streams["tau_measured"].data
    return ((tau - measured) ** 2).mean(axis=0) / measured.var(axis=0)


# ----------------------------------------------------------------------------- format families
def test_c3d_and_a_pot_table_give_a_log_stac_calibrates(tmp_path):
    """Markers in a 50 Hz C3D (mm, occlusions), pots in a 100 Hz lab CSV: on the mocap clock the
    import equals the simulated session, and STAC calibrates both the same."""
    run_ok(["simulate", "kinematics", "--robot", "finger", "--duration", "10", "--seed", "1", "-o",
         tmp_path / "sim.h5", "-q"])
    sim = load_log(tmp_path / "sim.h5")
    markers, pots = sim.streams["markers"], sim.streams["pots"]
    write_c3d(tmp_path / "mocap.c3d", markers.names, markers.data[::2] * 1000.0, rate=50.0, unit="mm")
    header = "t," + ",".join(f"{n} [V]" for n in pots.names)
    np.savetxt(tmp_path / "pots.csv", np.column_stack([sim.time, pots.data]), delimiter=",", header=header,
               comments="", fmt="%.17g")
    (tmp_path / "map.yaml").write_text(yaml.safe_dump(sort_keys=False, data={
        "robot": "finger",
        "sources": {"mocap": "mocap.c3d", "amp": {"file": "pots.csv", "time": "t"}},
        "streams": {"markers": {"source": "mocap"},
                    "pots": {"source": "amp", "columns": {f"{n} [V]": n for n in pots.names}, "unit": "V"}}}))
    run_ok(["import", tmp_path / "mocap.c3d", tmp_path / "pots.csv", "--map", tmp_path / "map.yaml",
         "-o", tmp_path / "imported.h5"])
    imported = load_log(tmp_path / "imported.h5")
    np.testing.assert_array_equal(imported.time, sim.time[::2])
    assert imported.streams["pots"].names == pots.names  # in the map's order
    np.testing.assert_array_equal(imported.streams["pots"].data, pots.data[::2])
    np.testing.assert_allclose(imported.streams["markers"].data, markers.data[::2], atol=1e-7)  # float32 in C3D
    assert np.array_equal(np.isnan(imported.streams["markers"].data), np.isnan(markers.data[::2]))
    direct = Log(sim.time[::2], {k: make_stream(s.names, s.data[::2]) for k, s in sim.streams.items()},
                 robot="finger", rate_hz=50.0)
    save_log(direct, tmp_path / "direct.h5")
    run_ok(["stac", tmp_path / "imported.h5", "-o", tmp_path / "imported.calib.yaml", "-q"])
    run_ok(["stac", tmp_path / "direct.h5", "-o", tmp_path / "direct.calib.yaml", "-q"])
    got, want = fitted_values(tmp_path / "imported.calib.yaml"), fitted_values(tmp_path / "direct.calib.yaml")
    assert got.keys() == want.keys()
    for key, value in want.items():
        assert got[key] == pytest.approx(value, rel=1e-4, abs=1e-7), key


@pytest.mark.parametrize("kind", ["ros1", "mcap"])
def test_a_bag_gives_a_log_sgp_fit_identifies(tmp_path, arm3, kind):
    q, qd, tau = (arm3.streams[k].data for k in ("q", "qd", "tau"))
    names = arm3.streams["q"].names
    bag = write_bag(tmp_path / ("run.bag" if kind == "ros1" else "run"), kind, names, arm3.time, q, qd, tau)
    (tmp_path / "map.yaml").write_text("robot: arm3\nsources: {run: {zero_time: true}}\nderive: [qdd]\n")
    result = run_ok(["import", bag, "--map", tmp_path / "map.yaml", "-o", tmp_path / "arm.h5"])
    assert "derived from q" in result.output
    log = load_log(tmp_path / "arm.h5")
    np.testing.assert_allclose(log.time, arm3.time, atol=1e-9)
    np.testing.assert_array_equal(log.streams["tau"].data, tau)
    true_qdd = arm3.streams["qdd"].data
    # central differences at 100 Hz (one-sided at the two ends, so those are left out): measured 3e-4
    err = np.abs(log.streams["qdd"].data - true_qdd)[2:-2].max(axis=0)
    assert (err < 2e-3 * np.abs(true_qdd).max(axis=0)).all(), err
    assert (_fit_and_predict(tmp_path / "arm.h5", tmp_path) < 0.01).all()


def test_a_rostopic_csv_gives_a_log_sgp_fit_identifies(tmp_path, arm3):
    q, qd, tau = (arm3.streams[k].data for k in ("q", "qd", "tau"))
    path = write_rostopic_csv(tmp_path / "js.csv", arm3.streams["q"].names, arm3.time, q, qd, tau)
    (tmp_path / "map.yaml").write_text("sources: {js: {zero_time: true}}\nderive: [qdd]\n")
    run_ok(["import", path, "--map", tmp_path / "map.yaml", "--robot", "arm3", "-o", tmp_path / "arm.h5", "-q"])
    assert load_log(tmp_path / "arm.h5").robot == "arm3"
    assert (_fit_and_predict(tmp_path / "arm.h5", tmp_path) < 0.01).all()


def test_figaroh_tx40_tables_through_the_committed_map(tmp_path):
    """Motor-side TX40 tables at 5 kHz, made from a simulated run through motor = R (q − zero) and
    c = R⁻ᵀ τ: the committed map gives the joint side back, and sgp-fit accepts the log."""
    run_ok(["simulate", "dynamics", "--robot", "tx40", "--rate", "5000", "--duration", "2", "--seed", "2",
         "-o", tmp_path / "sim.h5", "-q"])
    sim = load_log(tmp_path / "sim.h5")
    R = np.diag([32.0, 32, 45, -48, 45, 32])
    R[5, 4] = 32.0
    motor = (sim.streams["q"].data - [0, -np.pi / 2, np.pi / 2, 0, 0, 0]) @ R.T
    current = np.linalg.solve(R.T, sim.streams["tau"].data.T).T
    head = ",".join(f"Joint_{i}" for i in range(1, 7))
    for name, table in (("pos_read_data.csv", motor), ("curr_data.csv", current)):
        np.savetxt(tmp_path / name, table, delimiter=",", header=head, comments="", fmt="%.17g")
    # the committed conversions; the cut-off raised to 40 Hz for the simulator's faster excitation
    mapping = yaml.safe_load((REAL_MAPS / "tx40.map.yaml").read_text())
    mapping["filter"]["cutoff_hz"] = 40
    (tmp_path / "tx40.map.yaml").write_text(yaml.safe_dump(mapping))
    run_ok(["import", tmp_path / "pos_read_data.csv", tmp_path / "curr_data.csv", "--map",
         tmp_path / "tx40.map.yaml", "-o", tmp_path / "tx40.h5", "-q"])
    log = load_log(tmp_path / "tx40.h5")
    assert log.robot == "tx40" and log.rate_hz == 200.0
    # the import low-passes at 5 kHz and keeps every 25th sample: the same filter on the simulated
    # joint side must give the same values (the transmission and offsets are linear, so they commute)
    idx = np.searchsorted(sim.time, log.time)
    for key in ("q", "tau"):
        want = lowpass(sim.streams[key].data, 5000.0, 40.0)[idx]
        np.testing.assert_allclose(log.streams[key].data, want, atol=1e-9 * np.abs(want).max())
    run_ok(["sgp-fit", tmp_path / "tx40.h5", "--model", "pr", "-o", tmp_path / "fit.sgp", "-q"])


def test_the_shipped_real_logs_are_accepted_by_sgp_fit(tmp_path):
    for name in ("tx40", "tiago"):
        run_ok(["sgp-fit", REAL_MAPS / f"{name}.h5", "--model", "pr", "-o", tmp_path / f"{name}.sgp", "-q"])


# ----------------------------------------------------------------------------- bad input
@pytest.fixture
def csv_file(tmp_path):
    path = tmp_path / "a.csv"
    path.write_text("time,q.j1,tau.j1\n0,0,0\n0.01,0.1,1\n0.02,0.2,2\n")
    return path


@pytest.mark.parametrize("args", [
    ["import"],  # no SRC, no -o
    ["import", "{csv}"],  # no -o
    ["import", "{csv}", "-o", "{out}", "--rate", "-1"],
    ["import", "{csv}", "-o", "{out}", "--bogus"],
])
def test_usage_errors_exit_2_with_one_line(tmp_path, csv_file, args):
    args = [a.format(csv=csv_file, out=tmp_path / "o.h5") for a in args]
    result = runner.invoke(app, args)
    assert result.exit_code == 2, result.output
    assert one_line_error(result).startswith("error: ")


@pytest.mark.parametrize("map_text, extra, message", [
    (None, ["{missing}"], "missing.csv: no such file"),
    ("streams: {tua: {}}\n", [], "unknown stream 'tua' .* did you mean 'tau'"),
    ("streams: {q: {columns: {q.j2: j2}}}\n", [], "no column 'q.j2' .* did you mean 'q.j1'"),
    ("streams: {q: {columns: [q.j1], unit: dgr}}\n", [], "unknown unit 'dgr' .* did you mean 'deg"),
    ("window: [5, 6]\n", [], r"window \[5, 6\] s holds fewer than 2 samples"),
    ("sources: {x: {file: b.csv}}\n", [], "a.csv matches no source in the map"),
    ("streams: [q\n", [], "not valid YAML"),
])
def test_bad_input_is_one_line_exit_1_and_writes_nothing(tmp_path, csv_file, map_text, extra, message):
    args = ["import", str(csv_file)] + [e.format(missing=tmp_path / "missing.csv") for e in extra]
    if map_text is not None:
        (tmp_path / "m.yaml").write_text(map_text)
        args += ["--map", str(tmp_path / "m.yaml")]
    result = runner.invoke(app, args + ["-o", str(tmp_path / "out.h5")])
    assert result.exit_code == 1, result.output
    assert re.search(message, one_line_error(result)), result.output
    assert not (tmp_path / "out.h5").exists()


def test_output_must_be_a_log_and_not_a_source(tmp_path, csv_file):
    assert "a log is written as .h5, .hdf5 or .csv" in one_line_error(runner.invoke(app, ["import", str(csv_file),
                                                                                       "-o", str(tmp_path / "o.txt")]))
    assert "an input of the command" in one_line_error(runner.invoke(app, ["import", str(csv_file), "-o",
                                                                            str(tmp_path / "a.csv")]))
    result = run_ok(["import", csv_file, "-o", tmp_path / "o.csv"])  # a diegocal CSV is fine
    assert "robot" in result.output and load_log(tmp_path / "o.csv").streams["tau"].names == ("j1",)


def test_epoch_stamps_print_a_span_and_a_date(tmp_path):
    # the case: header stamps in Unix time printed "1.7e+09 .. 1.7e+09"
    t = np.arange(100) * 0.01
    bag = write_bag(tmp_path / "run.bag", "ros1", ["j1"], t, t[:, None])
    result = run_ok(["import", bag, "-o", tmp_path / "run.h5"])
    assert "1.7e+09" not in result.output
    assert "0.99 s from 2023-11-14 22:13:20.000 UTC" in result.output
    zeroed = run_ok(["import", bag, "--map", _write(tmp_path / "m.yaml", "sources: {run: {zero_time: true}}\n"),
                  "-o", tmp_path / "zeroed.h5"])
    assert "0 .. 0.99 s (0.99 s)" in zeroed.output


def _write(path, text):
    path.write_text(text)
    return path


def test_a_truncated_c3d_exits_1_and_writes_nothing_or_warns_when_allowed(tmp_path):
    full = write_c3d(tmp_path / "t.c3d", ["m1", "m2"], np.ones((2000, 2, 3)), rate=100.0)
    (tmp_path / "cut.c3d").write_bytes(full.read_bytes()[:20000])
    result = runner.invoke(app, ["import", str(tmp_path / "cut.c3d"), "-o", str(tmp_path / "cut.h5")])
    assert result.exit_code == 1
    assert "header announces 2000 frames (20 s), the file holds 577" in one_line_error(result)
    assert not (tmp_path / "cut.h5").exists()
    mapping = _write(tmp_path / "m.yaml", "sources: {cut: {allow_truncated: true}}\n")
    kept = run_ok(["import", tmp_path / "cut.c3d", "--map", mapping, "-o", tmp_path / "cut.h5", "-q"])
    assert "warning:" in kept.output and "importing the 577 frames read" in kept.output
    assert load_log(tmp_path / "cut.h5").n_samples == 577


def test_brackets_in_a_message_or_a_column_are_text_not_markup(tmp_path):
    # a user trial: `t [s]` printed as `t `, and a header `t [/s]` raised rich's MarkupError
    (tmp_path / "b.csv").write_text("t [/s],x\n0,1\n1,2\n")
    result = runner.invoke(app, ["import", str(tmp_path / "b.csv"), "-o", str(tmp_path / "o.h5")])
    assert result.exit_code == 1, result.output
    assert "columns: t [/s], x" in one_line_error(result) and "internal error" not in result.output


def test_a_robot_path_is_stored_absolute_and_read_from_the_maps_folder(tmp_path, csv_file, monkeypatch):
    # a user trial: the log kept `../docs/example_robot` as typed, usable from that folder only
    (tmp_path / "lab" / "robot").mkdir(parents=True)
    urdf = tmp_path / "lab" / "robot" / "one.urdf"
    urdf.write_text('<robot name="one"><link name="base"/><link name="l1"/><joint name="j1" type="revolute">'
                    '<parent link="base"/><child link="l1"/><axis xyz="0 0 1"/>'
                    '<limit lower="-3" upper="3" effort="1" velocity="1"/></joint></robot>')
    (tmp_path / "lab" / "m.yaml").write_text("robot: robot/one.urdf\n")
    monkeypatch.chdir(tmp_path)
    run_ok(["import", csv_file, "--map", tmp_path / "lab" / "m.yaml", "-o", tmp_path / "o.h5"])
    assert load_log(tmp_path / "o.h5").robot == str(urdf.resolve())
    run_ok(["import", csv_file, "--robot", "lab/robot/one.urdf", "-o", tmp_path / "p.h5"])
    assert load_log(tmp_path / "p.h5").robot == str(urdf.resolve())
    run_ok(["import", csv_file, "--robot", "arm3", "-o", tmp_path / "q.h5"])
    assert load_log(tmp_path / "q.h5").robot == "arm3"  # a bundled robot keeps its name
    (tmp_path / "lab" / "arm3").mkdir()  # a results folder beside the map, named like the robot
    (tmp_path / "lab" / "n.yaml").write_text("robot: arm3\n")
    run_ok(["import", csv_file, "--map", tmp_path / "lab" / "n.yaml", "-o", tmp_path / "r.h5"])
    assert load_log(tmp_path / "r.h5").robot == "arm3"
