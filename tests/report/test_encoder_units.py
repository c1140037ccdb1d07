"""A robot with an encoder (user trial on a Unitree Z1: five rotary pots, an encoder on joint 6).

Each sensor type's numbers are in its own unit (an encoder reads rad, not V: its noise σ, residual,
bias); the report's words say which gains and biases the fit estimated, which are fixed by design
(an encoder's gain) and which are gauges held at nominal, and why, never that no marker moves with
a joint whose markers it turns; a prediction log is said to be one."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import pytest
from typer.testing import CliRunner

from diegocal.cli import app
from diegocal.io import load_log, load_yaml
from diegocal.io.describe import describe_log
from diegocal.report.logs import pot_units, stream_table, summary_lines
from diegocal.report.registry import ReportContext
from diegocal.report.stac_pages import (
    _calibration,
    _evaluation,
    abstract,
    key_rows,
    pot_table,
    residual_caption,
)
from diegocal.report.stac_plots import plot_sigma
from diegocal.robot import load_robot
from tests.report.encoder_arm import make_robot, save_session

runner = CliRunner()


def _cli(*args):
    r = runner.invoke(app, [str(a) for a in args])
    assert r.exit_code == 0, r.output
    return r


@pytest.fixture(scope="module")
def arm(tmp_path_factory):
    """(robot dir, log, calib.yaml, prediction log of a second session) of the encoder arm."""
    d = tmp_path_factory.mktemp("encoder_arm")
    robot = make_robot(d / "arm")
    log = save_session(robot, d / "kin.h5", seed=1)
    held = save_session(robot, d / "held.h5", seed=2, occlusion=0.0)
    _cli("stac", log, "-o", d / "kin.calib.yaml", "-q")
    _cli("predict", d / "kin.calib.yaml", held, "-o", d / "held.pred.h5", "-q")
    return robot, log, d / "kin.calib.yaml", d / "held.pred.h5"


def test_each_sensor_type_is_in_its_own_unit(arm):
    """Trial item 1: 'noise σ, encoder 1.52 mV', 'residual RMS, encoder 0.265 mV', bias [V]."""
    robot, _, calib, _ = arm
    cal, ev = _calibration(calib), _evaluation(calib, ReportContext())
    units = {r[0].split(" (")[0]: r[2] for r in key_rows(cal, ev)}
    assert units["noise σ, encoder"] == "mrad" and units["noise σ, rotary"] == "mV"
    assert units["residual RMS, encoder"] == "mrad" and units["residual RMS, rotary"] == "mV"
    assert units["noise σ, markers"] == "mm"
    words = " ".join(abstract(calib, ReportContext()))
    assert "encoders" in words and " mrad RMS" in words and "encoder pots" not in words
    _, rows, _ = pot_table(cal, load_robot(robot))
    wrist = {r[0]: r for r in rows}["wrist"]
    assert (wrist[4], wrist[7]) == ("1", "rad")  # gain unit, bias unit
    assert {r[7] for r in rows if r[0] != "wrist"} == {"V"}
    assert "encoder in rad" in residual_caption(ev) and "rotary in V" in residual_caption(ev)
    ax = plot_sigma(cal)  # the pots' pooled σ mixes V and rad: each type's own σ instead
    labels = ax.get_legend_handles_labels()[1]
    plt.close(ax.figure)
    assert "encoder (rad), final" in labels and "rotary (V), final" in labels and "pots (V)" not in labels


def test_a_log_says_which_pots_read_another_unit(arm):
    robot, log_path, _, _ = arm
    log = load_log(log_path)
    others = pot_units(log)
    assert others == {"wrist": "rad"}
    _, rows = stream_table(describe_log(log), others)
    assert {r[0]: r[2] for r in rows}["pots"] == "V; rad (wrist)"


def test_the_words_say_which_gains_and_biases_were_estimated_and_why(arm):
    """Trial item 2: the encoder's bias is a leaf gauge (markers h1-h3 turn with the wrist), its gain
    1 by design; the shoulder's bias a root gauge. Not 'keep their nominal gain and bias: no marker
    moves with their joints', nor 'calibrated the gain and bias of 3 pots'."""
    robot, _, calib, _ = arm
    cal = _calibration(calib)
    words = " ".join(abstract(calib, ReportContext()))
    assert "no marker moves" not in words and "the gain and bias of 3 pots" not in words
    assert "It estimated 2 of the 3 gains (wrist's is 1 by design: an encoder reads" in words
    assert "and 1 of the 3 biases (shoulder's and wrist's are gauges, held at nominal" in words
    assert "2 pot bias(es) are held at nominal because the markers cannot fix that joint's zero" in words
    assert "wrist's, as every marker joint wrist moves is on link hand" in words
    assert "shoulder's, as joint shoulder moves every marker about an axis fixed in the base" in words
    assert "the positions of h1, h2, h3 are placed turned about their joint's axis" in words
    _, rows, _ = pot_table(cal, load_robot(robot))
    notes = {r[0]: r[-1] for r in rows}
    assert notes == {"shoulder": "bias nominal: gauge", "elbow": "", "wrist": "gain 1 by design; bias nominal: gauge"}
    assert cal.pot_roles() == {
        "shoulder": ("estimated", "gauge"),
        "elbow": ("estimated", "estimated"),
        "wrist": ("design", "gauge"),
    }


def test_a_prediction_log_is_said_to_be_one(arm):
    """Trial item 4: not 'a recorded log', not 'sh1 the most (0 %)'."""
    _, log_path, calib, pred_path = arm
    pred = load_log(pred_path)
    words = " ".join(summary_lines(describe_log(pred), pred.source))
    assert "It is a prediction, not a recording" in words and f"model {Path(calib).name}" in words
    assert "held.h5" in words and "recorded log" not in words and "the most" not in words
    recorded = load_log(log_path)
    words = " ".join(summary_lines(describe_log(recorded), recorded.source))
    assert "a recorded log" not in words or "simulated" in words
    assert "the most (" in words  # this one has occlusions: the worst marker is named


def test_the_commands_write_an_encoder_in_rad(arm, tmp_path):
    """stac's summary said "σ encoder (sensor unit)" and diagnose pooled the encoder's rad with
    the pots' V: each now says rad."""
    robot, log, calib, _ = arm
    out = _cli("stac", log, "-o", tmp_path / "again.calib.yaml").output
    assert "σ encoder (rad)" in out and "σ rotary (V)" in out
    _cli("diagnose", log, "--domain", "kinematics", "-o", tmp_path / "kin.diagnosis.yaml", "-q")
    units = load_yaml(tmp_path / "kin.diagnosis.yaml")["baseline"]["units"]
    assert units["wrist"] == "rad" and units["shoulder"] == "V" and units["h1"] == "m"
