"""Detection limits (diegocal/diagnose/limits.py): the smallest effect of each tested cause that a
diagnosis finds, checked against effects hidden at twice and half that size."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from toy import ToyAdapter, make_data  # noqa: E402

from diegocal.diagnose.engine import EngineOptions, run_unit  # noqa: E402
from diegocal.diagnose.limits import detectable, limits_words  # noqa: E402
from diegocal.evaluate import split_blocks  # noqa: E402


def _diagnose(seed, effects=()):
    t, x, y = make_data(seed, effects=list(effects))
    return run_unit(ToyAdapter(t, x, y), split_blocks(len(t)), EngineOptions()), x


def _quadratic_size(x: np.ndarray, rms: float) -> float:
    """The size of ``size · x²`` whose part the baseline (a x + b) cannot take up has RMS ``rms``."""
    A = np.column_stack([x, np.ones_like(x)])
    q = x**2 - A @ np.linalg.lstsq(A, x**2, rcond=None)[0]
    return rms / float(np.sqrt(np.mean(q**2)))


def test_an_effect_twice_its_detection_limit_is_found_and_one_half_of_it_is_not():
    """The limit a clean log gives for a curve on c1 (80 % found there): at twice that RMS the
    curve is named on nearly every log, at half it almost never."""
    limits = []
    for seed in range(3):
        d, _ = _diagnose(seed)
        limits += [x["rms"] for x in d.detection_limits if (x["cause"], x["channel"]) == ("square", "c1")]
    assert len(limits) == 3 and all(np.isfinite(limits))
    limit = float(np.median(limits))
    found = {}
    for multiple in (0.5, 2.0):
        hits = 0
        for seed in range(100, 110):
            x = make_data(seed)[1]  # the states do not depend on the effects
            d, _ = _diagnose(seed, [("quadratic", "c1", _quadratic_size(x[:, 1], multiple * limit))])
            hits += any(f.channel == "c1" and f.cause in ("square", "poly") for f in d.findings)
        found[multiple] = hits
    assert found[2.0] >= 9 and found[0.5] <= 2, found


def test_a_found_cause_has_no_limit_and_the_rest_are_least_detectable_first():
    d, _ = _diagnose(0, [("bump", "c0", 0.5)])
    assert ("bump", "c0") in {(f.cause, f.channel) for f in d.findings}
    pairs = [(x["cause"], x["channel"]) for x in d.detection_limits]
    assert ("bump", "c0") not in pairs and ("square", "c1") in pairs
    ranked = [x["of_residual"] for x in d.detection_limits]
    assert ranked == sorted(ranked, reverse=True)


def test_the_limit_is_the_larger_of_the_tests_power_and_the_gain_a_finding_needs():
    rng = np.random.default_rng(2)
    r, a = rng.normal(size=400), rng.normal(size=400)
    error = float(r @ r)
    # a weak test (large se): its power sets the limit, (threshold + 0.84) se times the correction's RMS
    rms, multiple, by = detectable(0.5, 3.0, r, a, error, 2.0, 0.05)
    assert by == "power"
    assert rms == pytest.approx(3.8416 * 0.5 * np.sqrt(np.mean(a * a)) / 2.0)
    assert multiple == pytest.approx(2.0 * rms / np.sqrt(np.mean(r * r)))
    # a strong test: the effect must still remove 5 % of the error, e² n = 0.05 / 0.95 Σ r²
    rms, multiple, by = detectable(1e-4, 3.0, r, a, error, 1.0, 0.05)
    assert by == "min_gain"
    assert rms**2 * r.size == pytest.approx(0.05 / 0.95 * error)
    assert detectable(float("inf"), 3.0, r, a, error, 1.0, 0.05)[0] == float("inf")


def test_the_limits_in_words_say_which_bar_sets_them_and_name_the_least_detectable():
    limits = [
        {"cause": "sensor_nonlinearity", "channel": "wrist_pot", "seen_on": "hand_m0", "rms": 2.7e-4, "unit": "m",
         "of_residual": 1.8, "by": "power"},
        {"cause": "spring", "channel": "joint1", "seen_on": "joint1", "rms": 0.002, "unit": "N·m", "of_residual": 0.23,
         "by": "min_gain"},
    ]
    words = limits_words(limits)
    assert words.startswith("2 tested cause-channel pairs, 1 limited by the gain a finding needs and 1 by the "
                            "data's power, are found once their effect is 0.23-1.8× the residual RMS on its channel")
    least = "least detectable: sensor_nonlinearity on wrist_pot (0.00027 m RMS on hand_m0, 1.8× the residual there)"
    assert least in words
    assert limits_words([]) == ""
    tied = limits_words([limits[1], {**limits[1], "channel": "joint2"}])
    assert tied.endswith("are found once their effect is 0.23× the residual RMS on its channel")  # no ties listed


def test_an_armature_the_identified_rigid_body_takes_up_is_said_not_testable():
    """arm3's joint2 armature lies in the identified rigid body's span: no candidate is offered and
    nothing is named; the limits say it cannot be tested, where a joint3 armature gets a finite one."""
    from diegocal.diagnose import DiagnoseOptions, diagnose
    from diegocal.robot import load_robot
    from diegocal.robot.model import BUNDLED_ROBOTS
    from diegocal.sim.dynamics import DynamicsOptions, simulate_dynamics

    robot = load_robot(BUNDLED_ROBOTS / "arm3")
    opts = DynamicsOptions(duration=20.0, effects=("armature:joint2=0.05",), noise=0.01)
    log = simulate_dynamics(robot, opts, np.random.default_rng(4))
    d = diagnose(log, robot, DiagnoseOptions(domain="dynamics"))
    assert not any(f.cause == "armature" for f in d.findings)
    limits = {(x["cause"], x["channel"]): x for u in d.units for x in u.detection_limits}
    assert limits[("armature", "joint2")]["by"] == "span" and limits[("armature", "joint2")]["rms"] == float("inf")
    assert np.isfinite(limits[("armature", "joint3")]["rms"])
    words = limits_words(d.units[0].detection_limits)
    assert "not testable, the model's own parameters taking them up whole: " in words and "armature on joint2" in words


def test_a_limit_is_the_effect_s_before_the_model_takes_its_part():
    """A user trial's Kinova spring: the identified rigid body took up 99.7 % of it, and the limit
    (the correction's RMS) said 0.074 N·m where the spring's own torque needed 1.7 N·m RMS. An
    adapter that projects the model's span out of a candidate says how much of its columns are left
    (``Candidate.visible``), and the limit is the correction's over that share."""
    from diegocal.diagnose.selection import evaluate_candidates
    from diegocal.diagnose.types import Candidate, Residuals
    from diegocal.terms import Parameter, Term

    rng = np.random.default_rng(5)
    T = 3000
    train, val = np.zeros(T, bool), np.zeros(T, bool)
    train[:1500], val[1500:] = True, True
    column = np.sin(np.linspace(0.0, 40.0, T))[:, None]
    res = Residuals({"j": rng.normal(0.0, 0.1, T)}, {"j": "N·m"}, {"time": np.arange(T) * 0.01}, {"j": ()})
    term = Term("spring", "j", (Parameter("k"),))
    limits = [
        evaluate_candidates([Candidate(term, {"j": column}, visible=v)], res, {"j": 1.0}, train, val,
                            EngineOptions())[0].detectable
        for v in (1.0, 0.1)
    ]
    assert limits[0][0] == limits[1][0] == "j" and limits[0][3] == limits[1][3]
    assert limits[1][1] == pytest.approx(10.0 * limits[0][1]) and limits[1][2] == pytest.approx(10.0 * limits[0][2])
