"""One fit per model: the held-out RMSE diagnosis.yaml writes for the extended model is what
``diegocal predict`` gives with the saved extended model on the same held-out blocks, per domain
(kinematics: each reading predicted from the others, ``--from others``; a static-pose log whose link
geometry the diagnosis fitted, too)."""

from __future__ import annotations

import numpy as np
import pytest
from typer.testing import CliRunner

from diegocal.cli import app
from diegocal.io import load_log, load_yaml, save_log

CASES = {
    "kinematics": (
        ["simulate", "kinematics", "--robot", "finger", "--duration", "6", "--seed", "2",
         "--effect", "sensor_nonlinearity:fds"],
        ["--domain", "kinematics"],
        ["--from", "others", "--to", "pots,markers"],
        ("pots", "markers"),
    ),
    "dynamics": (
        ["simulate", "dynamics", "--robot", "arm3", "--duration", "12", "--rate", "50", "--seed", "2",
         "--effect", "torque_offset:joint2"],
        ["--domain", "dynamics"],
        [],
        ("tau",),
    ),
    "pneumatics": (
        ["simulate", "pneumatics", "--robot", "diego", "--duration", "10", "--seed", "3",
         "--effect", "chamber_leak:r_elbow.flex=2e-6"],
        ["--domain", "pneumatics", "--chamber", "r_elbow.flex", "--chamber", "r_elbow.ext"],
        [],
        ("pressure",),
    ),
}


def _run(*args):
    res = CliRunner().invoke(app, [str(a) for a in args])
    assert res.exit_code == 0, res.output
    return res


def _heldout(log, blocks) -> np.ndarray:
    t = log.time
    mask = np.zeros(t.size, bool)
    for a, b in blocks:
        mask |= (t >= a - 1e-9) & (t <= b + 1e-9)
    return mask


@pytest.mark.parametrize("domain", list(CASES))
def test_the_held_out_rmse_written_is_what_predict_gives_with_the_saved_model(domain, tmp_path):
    simulate, diagnose, predict, streams = CASES[domain]
    log_path = tmp_path / "run.h5"
    _run(*simulate, "-o", log_path, "--quiet")
    d = _diagnosed(log_path, diagnose, tmp_path)
    assert _predicted(log_path, d, predict, streams, tmp_path, rel=1e-6) >= 2


def test_link_geometry_the_diagnosis_fitted_is_what_predict_uses(tmp_path):
    """A static-pose session of a Panda whose link geometry is off (experiments/
    static_geometry_generator.py): the extended calib.yaml carries the geometry, and predicting the
    markers with it reproduces the held-out RMSE written, from the others (the score's own path)
    and from the encoders alone (one tool point: its others are the encoders; the score's
    leave-one-out is the linearised deletion, so to 1e-4)."""
    gen = pytest.importorskip("experiments.static_geometry_generator")
    if not (gen.SHARE / gen.ROBOTS["panda"][0]).is_file():
        pytest.skip("example-robot-data is not installed")
    _, log = gen.simulate(tmp_path, gen.Session("panda", 60, 1, seed=3))
    log_path = tmp_path / "panda_static.h5"
    save_log(log, log_path)
    d = _diagnosed(log_path, ["--domain", "kinematics"], tmp_path)
    assert [f["cause"] for f in d["findings"]] == ["joint_geometry"]
    assert any(t["cause"] == "joint_geometry" for t in load_yaml(tmp_path / d["extended_model"])["terms"])
    assert _predicted(log_path, d, ["--from", "others", "--to", "pots,markers"], ("pots", "markers"), tmp_path) >= 2
    assert _predicted(log_path, d, ["--from", "pots", "--to", "markers"], ("markers",), tmp_path, rel=1e-4) == 1


def _diagnosed(log_path, diagnose, tmp_path) -> dict:
    _run("diagnose", log_path, *diagnose, "-o", tmp_path / "run.diagnosis.yaml", "--quiet")
    d = load_yaml(tmp_path / "run.diagnosis.yaml")
    assert d["findings"], "the hidden effect should be found"
    return d


def _predicted(log_path, d, predict, streams, tmp_path, rel=1e-6) -> int:
    """How many channels' held-out RMSE ``diegocal predict`` with the extended model reproduces
    (each checked to ``rel``)."""
    _run("predict", tmp_path / "run.diagnosis.yaml", log_path, *predict, "-o", tmp_path / "pred.h5", "--quiet")
    log, pred = load_log(log_path), load_log(tmp_path / "pred.h5")
    held = _heldout(log, d["blocks"]["heldout"])
    written = d["extended"]["heldout_rmse"]
    checked = 0
    for stream in streams:
        measured = log.stream(stream)
        predicted = pred.stream(stream)
        for name in predicted.names:
            if written.get(name) is None:
                continue
            e = (measured.column(name) - predicted.column(name))[held].reshape(int(held.sum()), -1)
            ok = np.isfinite(e).all(axis=1)
            rmse = float(np.sqrt(np.mean(np.sum(e[ok] ** 2, axis=1))))
            assert rmse == pytest.approx(written[name], rel=rel), (stream, name)
            checked += 1
    return checked
