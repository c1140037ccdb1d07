"""The scale and sizes benches' case for tests (``bench/bench_sgp_sizes.py``): arm3 at 50 Hz with
the hidden friction on joint 3 above 1.78 rad, an ``n``-sample training run of ``seed`` and
2,000 samples of run 1000 + ``seed``'s trajectory of the same robot to test on."""

from types import SimpleNamespace

import numpy as np

from diegocal.robot import BUNDLED_ROBOTS, load_robot
from diegocal.sgp import SGPOptions, fit_dynamics
from experiments.sgp.common import friction_case, same_robot


def held_out_run(seed: int, n: int = 200) -> SimpleNamespace:
    """arm3, train and test (Logs), nmse(model) -> (3,) held-out nMSE per joint, pr: PR's."""
    arm3 = load_robot(BUNDLED_ROBOTS / "arm3")
    train = friction_case(arm3, n, seed).slice(0, n)
    test = friction_case(arm3, 2000, 1000 + seed, same_robot(train, arm3)).slice(0, 2000)
    tau = test.stream("tau").select(arm3.joint_names).data

    def nmse(model):
        return np.mean((model.predict(test).tau - tau) ** 2, axis=0) / tau.var(axis=0)

    pr = nmse(fit_dynamics(train, arm3, SGPOptions(kind="pr")))
    return SimpleNamespace(arm3=arm3, train=train, test=test, nmse=nmse, pr=pr)
