"""experiments/pneumatic_generator.py: its flow, its integrator and its effects, on short logs."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from diegocal.io import load_log, save_log
from experiments import pneumatic_generator as gen


def test_thin_plate_flow_is_choked_below_the_critical_ratio_and_its_derivatives_are_right():
    area = 1e-6
    up = 600e3
    m1, _, dd1 = gen.flow(up, 0.3 * up, area)
    m2, _, _ = gen.flow(up, 0.5 * up, area)
    assert m1 == pytest.approx(m2) and dd1 == 0.0  # choked: the downstream pressure does not matter
    assert gen.flow(up, up, area)[0] == 0.0
    assert gen.flow(200e3, 300e3, area)[0] == pytest.approx(-gen.flow(300e3, 200e3, area)[0])
    for p1, p2 in ((600e3, 400e3), (300e3, 420e3), (620e3, 600e3)):
        m, d1, d2 = gen.flow(p1, p2, area)
        eps = 1.0
        fd1 = (gen.flow(p1 + eps, p2, area)[0] - gen.flow(p1 - eps, p2, area)[0]) / 2
        fd2 = (gen.flow(p1, p2 + eps, area)[0] - gen.flow(p1, p2 - eps, area)[0]) / 2
        assert d1 == pytest.approx(fd1, rel=1e-4) and d2 == pytest.approx(fd2, rel=1e-4)


def test_the_2khz_rosenbrock_step_follows_a_stiff_reference_solution():
    # one chamber filling through its valve from a hose behind a restricted line, over 20 ms: the
    # hardest case (choked filling, the hose sagging by 100 kPa); over whole logs the 2 kHz
    # pressures differ from 16 kHz ones by 0.04-0.09 kPa RMS
    valves = gen.hardware(1, 3)
    batch = gen._Batch(
        np.array([620e3]), np.array([100e3]), np.array([0.5e-6]), np.array([1.0e-6]), np.zeros(1, int), valves
    )
    a_c, a_r = valves.areas(np.array([6.2]))
    vol, rate = np.array([1.2e-5]), np.array([-2e-4])

    def f(t, y):
        fp, fm = batch.rhs(np.array([y[0]]), np.array([y[1]]), a_c, a_r, vol, rate)[:2]
        return [fp[0], fm[0]]

    ref = solve_ivp(f, (0.0, 0.02), [150e3, 620e3], method="Radau", rtol=1e-10, atol=1e-3, dense_output=True)
    assert ref.sol(0.02)[1] < 600e3  # the hose sags while the chamber fills
    p, m, dt = np.array([150e3]), np.array([620e3]), 0.0005
    for k in range(40):
        p, m, _ = gen._ros2(batch, p, m, a_c, a_r, ((vol, rate), (vol, rate)), dt)
        want = ref.sol((k + 1) * dt)
        assert abs(p[0] - want[0]) < 500.0 and abs(m[0] - want[1]) < 1500.0  # Pa: below the sensor noise


@pytest.fixture(scope="module")
def logs():
    effects = (
        gen.Effect("valve_delay", "shoulder.flex", 0.045),
        gen.Effect("chamber_leak", "shoulder.ext", 0.6e-6),
        gen.Effect("supply_droop", "elbow.flex", 1.0e-6),
        gen.Effect("pressure_offset", "elbow.ext", -11.0),
    )
    opts = gen.GeneratorOptions(duration=4.0, seed=5)
    faulty, clean = gen.generate_many([gen.GeneratorOptions(duration=4.0, seed=5, effects=effects), opts])
    return faulty, clean


def test_effects_change_only_their_chamber_and_in_their_own_way(logs):
    faulty, clean = logs
    p, q = (lg.truth.signals["pressure"] for lg in (faulty, clean))
    assert np.array_equal(faulty.stream("valve").data, clean.stream("valve").data)  # the same session
    assert np.array_equal(faulty.stream("pots").data, clean.stream("pots").data)
    # the offset changes the reading, not the pressure
    assert np.array_equal(p.column("elbow.ext"), q.column("elbow.ext"))
    off = faulty.truth.signals["reading"].column("elbow.ext") - p.column("elbow.ext")
    assert np.allclose(off, -11.0)
    # a leak only lowers the pressure; a restricted supply line sags it while the chamber fills
    assert (p.column("shoulder.ext") <= q.column("shoulder.ext") + 1e-6).all()
    assert np.mean(q.column("shoulder.ext") - p.column("shoulder.ext")) > 20.0
    sag = next(e for e in faulty.truth.effects if e["cause"] == "supply_droop")["values"]
    assert sag["sag_max_kpa"] > 20.0 and sag["sag_p90_kpa"] < 0.3 * sag["sag_max_kpa"]
    # a valve delay shifts the response: the clean chamber's pressure 45 ms earlier fits best
    a, b = p.column("shoulder.flex"), q.column("shoulder.flex")
    errs = [np.mean((a[k:] - b[: b.size - k]) ** 2) for k in range(8)]
    assert int(np.argmin(errs)) in (4, 5)


def test_logs_round_trip_with_their_truth(logs, tmp_path):
    faulty, _ = logs
    save_log(faulty, tmp_path / "a.h5")
    back = load_log(tmp_path / "a.h5")
    assert back.truth.effects == faulty.truth.effects
    assert set(back.truth.signals) == {"q", "pressure", "reading"}
    assert back.robot == str(gen.ROBOT_DIR)
    assert np.allclose(back.stream("pressure").data, faulty.stream("pressure").data)


def test_the_same_seed_gives_the_same_log_and_the_hardware_stays_across_sessions():
    a = gen.generate(gen.GeneratorOptions(duration=1.0, seed=2))
    b = gen.generate(gen.GeneratorOptions(duration=1.0, seed=2))
    c = gen.generate(gen.GeneratorOptions(duration=1.0, seed=3))
    assert np.array_equal(a.stream("pressure").data, b.stream("pressure").data)
    assert not np.array_equal(a.stream("valve").data, c.stream("valve").data)
    assert a.truth.params["valves"] == c.truth.params["valves"]
