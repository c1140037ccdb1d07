"""All 76 diego chambers on thin-plate physics (slow: `make bench`).

Thesis §4.5.4 / Fig. 4.13: the 2-s open-loop drift is below 10 % of (Pc - Pr) for every chamber
and usually below 4 %. Trained on two 60-s sessions, checked on a third, held-out session.
"""

import numpy as np
import pytest

from diegocal.pneumatic import FitOptions, chamber_data, drift, fit_chambers
from diegocal.robot import load_robot, resolve_robot_dir
from diegocal.sim.pneumatics import PneumaticSimOptions, simulate_pneumatics


@pytest.mark.slow
def test_all_76_chambers_drift_less_than_10_percent_on_held_out_data():
    robot = load_robot(resolve_robot_dir("diego", None))
    names = robot.sensors.chamber_names
    assert len(names) == 76
    log = simulate_pneumatics(robot, PneumaticSimOptions(duration=60.0, sessions=3, seed=21))
    n = int(round(60.0 * log.rate_hz)) + 1
    train, held = log.slice(0, 2 * n), log.slice(2 * n, 3 * n)
    batch = fit_chambers(
        [chamber_data(train, robot.sensors, c) for c in names], FitOptions(), jobs=2
    )
    assert not batch.skipped
    d = np.array(
        [drift(batch.fits[c].params, chamber_data(held, robot.sensors, c)).final for c in names]
    )
    assert d.max() < 0.10, {names[i]: round(d[i], 3) for i in np.argsort(d)[-5:]}
    assert (d < 0.04).mean() > 0.6, np.percentile(d, [50, 75, 90])
