"""`simulate pneumatics`: streams, truth, integration accuracy, experiments and effects."""

import numpy as np
import pytest

from diegocal.errors import UnknownNameError
from diegocal.sim.effects import EffectError
from diegocal.sim.pneumatics import (
    PneumaticSimOptions,
    SimOptionError,
    robot_valves,
    simulate_pneumatics,
)
from diegocal.sim.thin_plate import steady_state_pressure


def test_log_has_the_contract_streams_and_truth(physics_log, robot):
    names = robot.sensors.chamber_names
    assert physics_log.streams["pressure"].names == names == physics_log.streams["valve"].names
    assert {"shoulder_pot", "elbow_pot"} <= set(physics_log.streams["pots"].names)
    u = physics_log.streams["valve"].data
    assert u.min() >= 3.0 and u.max() <= 7.0 and u.std() > 1.0  # §4.5: 3-7 V, explored
    p = physics_log.streams["pressure"].data
    assert np.percentile(p, 2) < 130 and np.percentile(p, 98) > 590  # room to supply
    truth = physics_log.truth
    assert truth.params["model"] == "thin-plate" and set(truth.params["valves"]) == set(names)
    assert truth.signals["q"].names == robot.joint_names
    noise = p - truth.signals["pressure"].data
    assert noise.std() == pytest.approx(0.3, rel=0.1)


def test_halving_the_internal_step_changes_samples_less_than_sensor_noise(robot):
    # §4.3: the dynamics are stiff; the exponential-midpoint sub-steps must have converged.
    logs = [
        simulate_pneumatics(robot, PneumaticSimOptions(duration=3.0, substeps=n, seed=4))
        for n in (20, 40)
    ]
    a, b = (lg.truth.signals["pressure"].data for lg in logs)
    diff = np.abs(a - b)
    assert np.sqrt(np.mean(diff**2)) < 0.3 / 3  # RMS well below the 0.3 kPa sensor noise
    assert diff.max() < 3 * 0.3


def test_steady_state_experiment_follows_the_physical_sigmoid(robot):
    # §4.3.1 / §4.5.2: locked cylinders, slow sweep -> pressure = p_ss(u) (up to the lag in the
    # sealed band, where only leakage moves the air).
    log = simulate_pneumatics(
        robot, PneumaticSimOptions(duration=40.0, experiment="steady-state", substeps=5, seed=2)
    )
    pots = log.streams["pots"].data
    assert np.ptp(pots, axis=0).max() < 1e-2  # locked: only noise
    u = log.streams["valve"].data
    pss = steady_state_pressure(u, robot_valves(robot), 620e3, 100e3) / 1e3
    err = np.abs(log.truth.signals["pressure"].data - pss)
    assert np.median(err) < 5.0 and np.percentile(err, 90) < 40.0


def test_effects_are_injected_and_recorded(robot):
    opts = dict(duration=3.0, substeps=5, seed=5)
    base = simulate_pneumatics(robot, PneumaticSimOptions(**opts))
    log = simulate_pneumatics(
        robot,
        PneumaticSimOptions(
            effects=(
                "pressure_offset:elbow.ext",
                "valve_delay:shoulder.flex",
                "chamber_leak:elbow.flex",
                "supply_droop:supply",
            ),
            **opts,
        ),
    )
    causes = {e["cause"]: e for e in log.truth.effects}
    assert (
        causes["pressure_offset"]["channel"] == "elbow.ext"
        and causes["supply_droop"]["channel"] == "supply"
    )
    i = robot.sensors.chamber_names.index("elbow.ext")
    shift = log.streams["pressure"].data[:, i] - log.truth.signals["pressure"].data[:, i]
    assert shift.mean() == pytest.approx(causes["pressure_offset"]["values"]["offset"], abs=0.1)
    # the delayed valve changes its chamber's pressure; the commands in the log are the same
    j = robot.sensors.chamber_names.index("shoulder.flex")
    np.testing.assert_array_equal(log.streams["valve"].data, base.streams["valve"].data)
    assert (
        np.abs(
            log.truth.signals["pressure"].data[:, j] - base.truth.signals["pressure"].data[:, j]
        ).max()
        > 50
    )


def test_bad_options_and_effects_fail_clearly(robot):
    with pytest.raises(EffectError, match="not a pneumatics effect"):
        simulate_pneumatics(robot, PneumaticSimOptions(duration=1.0, effects=("backlash",)))
    with pytest.raises(UnknownNameError, match="not a chamber"):
        simulate_pneumatics(
            robot, PneumaticSimOptions(duration=1.0, effects=("chamber_leak:nope",))
        )
    with pytest.raises(SimOptionError, match="experiment"):
        simulate_pneumatics(robot, PneumaticSimOptions(duration=1.0, experiment="wild"))


def test_effect_sizes_are_honoured_in_their_documented_units(robot):
    opts = dict(duration=3.0, substeps=5, seed=6)
    names = robot.sensors.chamber_names
    base = simulate_pneumatics(robot, PneumaticSimOptions(**opts)).truth.signals["pressure"].data

    def run(effect):
        log = simulate_pneumatics(robot, PneumaticSimOptions(effects=(effect,), **opts))
        return log, log.truth.signals["pressure"].data

    log, _ = run("pressure_offset:elbow.ext=1.5")
    i = names.index("elbow.ext")
    assert log.truth.effects[0]["values"]["offset"] == 1.5
    assert (log.streams["pressure"].data[:, i] - log.truth.signals["pressure"].data[:, i]).mean() == pytest.approx(
        1.5, abs=0.05
    )
    # a delay between two ticks lies between the two whole-tick delays (continuous time shift)
    j = names.index("shoulder.flex")
    moved = {d: np.abs(run(f"valve_delay:shoulder.flex={d}")[1][:, j] - base[:, j]).mean() for d in (0.01, 0.015, 0.02)}
    assert moved[0.01] < moved[0.015] < moved[0.02]
    # a bigger orifice leaks more; a bigger droop lowers the pressure more (chamber's own flow)
    k = names.index("elbow.flex")
    leak = [np.mean(base[:, k] - run(f"chamber_leak:elbow.flex={a}")[1][:, k]) for a in (0.05e-6, 0.2e-6)]
    assert 0 < leak[0] < leak[1]
    droop = [np.mean(base[:, k] - run(f"supply_droop:elbow.flex={g}")[1][:, k]) for g in (5.0, 20.0)]
    assert 0 < droop[0] < droop[1]
