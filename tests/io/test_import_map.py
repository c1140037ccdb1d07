"""Import maps, units and the signal steps of `diegocal import` (resampling, filters, derivatives)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from diegocal.io.importers import MapError, UnitError, derivatives, excitation_window, parse_map, resample
from diegocal.io.importers.mapping import per_channel
from diegocal.io.importers.units import factor, time_factor


# ----------------------------------------------------------------------------- units
def test_unit_factors_take_lab_units_to_the_log_units():
    assert factor("q", "deg") == pytest.approx(np.pi / 180)
    assert factor("q", "mm") == 1e-3 and factor("markers", "mm") == 1e-3 and factor("markers", "cm") == 1e-2
    assert factor("qd", "rpm") == pytest.approx(2 * np.pi / 60)
    assert factor("qdd", "deg/s^2") == pytest.approx(np.pi / 180)
    assert factor("tau", "mN·m") == 1e-3 and factor("tau", "Nm") == 1.0
    assert factor("pots", "counts") == 1.0  # sensor units: kept as they are
    assert time_factor("ms") == 1e-3 and time_factor("ns") == 1e-9


def test_unknown_units_name_the_known_ones_and_a_close_match():
    with pytest.raises(UnitError, match=r"unknown unit 'degs' for stream 'q' .* did you mean 'deg'\?"):
        factor("q", "degs")
    with pytest.raises(UnitError, match="'markers'"):
        factor("markers", "rad")  # a marker is a length
    with pytest.raises(UnitError, match="did you mean 'ms'"):
        time_factor("msec")


# ----------------------------------------------------------------------------- maps
def test_a_full_map_parses():
    m = parse_map({
        "robot": "arm", "sources": {"a": {"file": "a.csv", "time": "t", "time_unit": "ms"}, "b": "b.c3d"},
        "streams": {"q": {"source": "a", "columns": {"A": "j1"}, "unit": "deg", "side": "motor"},
                    "markers": {"source": "b", "columns": ["M1"]}},
        "transmission": {"ratio": [2.0]}, "clock": {"source": "b"}, "interpolation": "nearest",
        "filter": {"cutoff_hz": 5}, "derive": ["qd", "qdd"], "window": [1.0, 2.0]})
    assert m.robot == "arm" and [s.name for s in m.sources] == ["a", "b"] and m.sources[1].file == "b.c3d"
    assert m.streams[0].columns == (("A", "j1"),) and m.streams[1].columns == (("M1", "M1"),)
    assert m.ratio.shape == (1, 1) and m.clock.source == "b" and m.filter.order == 4
    assert m.window.start == 1.0 and not m.window.auto and m.derive == ("qd", "qdd")


@pytest.mark.parametrize("data, message", [
    ({"stream": {}}, "unknown key 'stream' .* did you mean 'streams'"),
    ({"streams": {"tua": {}}}, "unknown stream 'tua' .* did you mean 'tau'"),
    ({"streams": {"q": {"colums": ["a"]}}}, "unknown key 'colums' .* did you mean 'columns'"),
    ({"streams": {"q": {"source": "pso"}}, "sources": {"pos": {}}}, "no source 'pso' .* did you mean 'pos'"),
    ({"streams": {"q": {"columns": {"a": "j", "b": "j"}}}}, "channel 'j' is mapped twice"),
    ({"streams": {"q": {"side": "motors"}}}, "side must be joint or motor, got 'motors' — did you mean 'motor'"),
    ({"interpolation": "cubic"}, "interpolation 'cubic' is not one of linear, nearest, previous"),
    ({"derive": ["qdd", "tau"]}, "'tau' cannot be derived"),
    ({"derive": ["qd"], "streams": {"qd": {}}}, "qd is both mapped from a file and derived"),
    ({"transmission": {"ratio": [[1, 2, 3], [4, 5, 6]]}}, "square matrix"),
    ({"transmission": {"ratio": [[1, 2], [2, 4]]}}, "invertible"),
    ({"clock": {}}, "give rate_hz or source"),
    ({"clock": {"rate_hz": -5}}, "positive number"),
    ({"filter": {"order": 4}}, "cutoff_hz is required"),
    ({"filter": {"cutoff_hz": 5, "streams": ["markers"]}}, "markers cannot be filtered"),
    ({"window": [3, 1]}, "start 3.0 s must be before stop 1.0 s"),
    ({"window": "everything"}, "window must be auto"),
    ({"sources": {"a": {"time": "t", "rate_hz": 10}}}, "either a time column or rate_hz"),
    ({"sources": {"a": {"kind": "hdf"}}}, "kind 'hdf' is not one of csv, c3d, bag"),
])
def test_bad_maps_are_one_line_errors(data, message):
    with pytest.raises(MapError, match=message) as err:
        parse_map(data, where="m.yaml")
    assert "\n" not in str(err.value) and str(err.value).startswith("m.yaml: ")


def test_per_channel_values_by_list_mapping_and_default():
    names = ("a", "b", "c")
    assert per_channel(2.0, names, 1.0, "x") == [2.0, 2.0, 2.0]
    assert per_channel([1, 2, 3], names, 0, "x") == [1, 2, 3]
    assert per_channel({"b": "m", "*": "rad"}, names, None, "x") == ["rad", "m", "rad"]
    assert per_channel({"b": 5}, names, 0, "x") == [0, 5, 0]
    with pytest.raises(MapError, match="2 values for 3 channels"):
        per_channel([1, 2], names, 0, "x")
    with pytest.raises(MapError, match="no channel 'bb' .* did you mean 'b'"):
        per_channel({"bb": 1}, names, 0, "x")


# ----------------------------------------------------------------------------- resampling
@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**31), st.integers(3, 40))
def test_linear_resampling_is_numpy_interp_and_exact_at_samples(seed, n):
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.5, 1.5, n))
    x = rng.normal(size=(n, 2))
    time = np.sort(np.concatenate([rng.uniform(t[0], t[-1], 10), t[[0, n // 2, -1]]]))
    out = resample(x, t, time)
    for k in range(2):
        np.testing.assert_array_equal(out[:, k], np.interp(time, t, x[:, k]))


def test_nearest_previous_and_gaps():
    t = np.array([0.0, 1.0, 2.0, 10.0, 11.0])
    x = np.array([0.0, 10.0, 20.0, 100.0, 110.0])
    time = np.array([0.4, 0.6, 1.0, 5.0, 10.5])
    np.testing.assert_array_equal(resample(x, t, time, "nearest"), [0.0, 10.0, 10.0, 20.0, 100.0])
    np.testing.assert_array_equal(resample(x, t, time, "previous"), [0.0, 0.0, 10.0, 20.0, 100.0])
    gapped = resample(x, t, time, "linear", max_gap_s=2.0)  # 2..10 s is not bridged
    np.testing.assert_array_equal(gapped, [4.0, 6.0, 10.0, np.nan, 105.0])


def test_occluded_markers_stay_occluded_and_visible_samples_stay_exact():
    t = np.arange(6) * 0.01
    x = np.arange(18.0).reshape(6, 1, 3)
    x[3] = np.nan  # occluded in sample 3
    out = resample(x, t, np.array([0.02, 0.025, 0.04, 0.045]))
    np.testing.assert_array_equal(out[0, 0], x[2, 0])  # a sample hit exactly, its neighbour NaN
    assert np.isnan(out[1]).all()  # between a visible and an occluded sample
    np.testing.assert_array_equal(out[2, 0], x[4, 0])
    np.testing.assert_allclose(out[3, 0], (x[4, 0] + x[5, 0]) / 2)


# ----------------------------------------------------------------------------- derivatives, window
def test_zero_phase_derivatives_of_a_sine():
    rate = 200.0
    t = np.arange(0, 20, 1 / rate)
    w = 2 * np.pi * 0.5
    q = np.sin(w * t)[:, None]
    qf, qd, qdd = derivatives(q, rate, cutoff_hz=5.0)
    inner = slice(400, -400)  # away from the filter's edge transients
    np.testing.assert_allclose(qf[inner, 0], np.sin(w * t[inner]), atol=1e-3)
    np.testing.assert_allclose(qd[inner, 0], w * np.cos(w * t[inner]), atol=1e-2)
    np.testing.assert_allclose(qdd[inner, 0], -w * w * np.sin(w * t[inner]), atol=3e-2)


def test_excitation_window_with_margin():
    qd = np.zeros((1000, 2))
    qd[300:700, 1] = 0.5
    assert excitation_window(qd, 100.0, threshold=0.1, margin_s=0.5) == (250, 750)
    assert excitation_window(np.zeros((10, 2)), 100.0) == (0, 10)
