"""experiments/pneumatic_oov.py: each out-of-vocabulary shape changes what it says it changes, on
short sessions of the independent generator; the valve's play is a backlash of the command."""

from __future__ import annotations

import numpy as np
import pytest

from experiments import pneumatic_generator as gen
from experiments import pneumatic_oov as oov

SECONDS = 4.0


@pytest.fixture(scope="module")
def clean():
    return gen.generate(gen.GeneratorOptions(duration=SECONDS, substeps=5, seed=3))


def _shape(shape):
    log, chamber, size = oov.add_shape(shape, 3, chamber="elbow.flex", duration=SECONDS)
    return log, log.streams["pressure"].names.index("elbow.flex"), size


def test_sensor_shapes_change_one_chamber_s_reading_by_their_form_and_keep_its_noise(clean, monkeypatch):
    monkeypatch.setattr(oov, "SESSION", gen.GeneratorOptions(substeps=5))
    before = clean.streams["pressure"].data
    reading = clean.truth.signals["reading"].data
    room = gen.load_chambers().room / gen.KPA
    for shape in ("span_error", "zero_drift", "slow_sensor"):
        log, i, size = _shape(shape)
        after = log.streams["pressure"].data
        others = np.arange(after.shape[1]) != i
        assert np.array_equal(after[:, others], before[:, others]), shape
        change = after[:, i] - before[:, i]
        if shape == "span_error":
            assert change == pytest.approx(size * (reading[:, i] - room[i]), abs=1e-9)
            assert 4.0 <= np.sqrt(np.mean(change**2)) / 0.4 <= 10.0  # ratio × the sensor's noise
        elif shape == "zero_drift":
            assert change[0] == pytest.approx(0.0, abs=1e-12) and change[-1] == pytest.approx(size)
            assert np.all(np.diff(change) * np.sign(size) >= 0)
        else:  # a first-order lag: the reading moves towards the pressure, never past it
            lagged = reading[:, i] + change
            assert oov.SLOW_S[0] <= size <= oov.SLOW_S[1]
            step = np.diff(lagged)
            gap = reading[1:, i] - lagged[:-1]
            assert np.all(step * gap >= -1e-9) and np.all(np.abs(step) <= np.abs(gap) + 1e-9)


def test_a_valve_with_play_sees_a_command_that_holds_through_reversals():
    u = np.r_[np.linspace(4.0, 6.0, 21), np.linspace(6.0, 4.0, 21)]
    out = gen.play(u, 0.4)
    assert np.all(np.abs(out - u) <= 0.2 + 1e-12)
    # rising, the spool trails the command by half the play; after the reversal at 6 V it holds
    # until the command has come down the whole play (to 5.6 V), then trails it from above
    assert out[20] == pytest.approx(5.8) and np.all(out[21:26] == out[20]) and out[26] < out[20]
    assert np.array_equal(gen.play(u, 0.0), u)


def test_valve_play_is_physics_the_log_records_the_command_sent(clean, monkeypatch):
    monkeypatch.setattr(oov, "SESSION", gen.GeneratorOptions(substeps=5))
    log, i, size = _shape("valve_play")
    assert oov.PLAY_V[0] <= size <= oov.PLAY_V[1]
    assert np.array_equal(log.streams["valve"].data, clean.streams["valve"].data)
    p, p0 = log.truth.signals["pressure"].data, clean.truth.signals["pressure"].data
    others = np.arange(p.shape[1]) != i
    assert np.array_equal(p[:, others], p0[:, others])
    assert np.sqrt(np.mean((p[:, i] - p0[:, i]) ** 2)) > 1.0  # kPa: the chamber fills and empties late
