"""`diagnose --domain pneumatics` on the independent generator (experiments/pneumatic_generator.py),
whose faults have their physical shape: a restricted supply line (an orifice before a hose) is
named ``supply_droop`` with the hose shape, a delayed valve ``valve_delay`` with its delay within
two standard errors of the truth, and the clean chambers give nothing; a declined offset and a
drifting zero are not named. Seeds fixed; three 60-s logs, generated together at 1 kHz (10
sub-steps per tick, half the benches' 20: the suite's time).
"""

from __future__ import annotations

from dataclasses import replace

import pytest

from diegocal.diagnose import DiagnoseOptions, diagnose
from diegocal.robot import load_robot
from experiments import pneumatic_generator as gen


@pytest.fixture(scope="module")
def sessions() -> dict:
    """The file's three sessions, integrated together (``generate_many``: one pass for the three)."""
    from experiments.pneumatic_oov import session

    effects = (gen.Effect("supply_droop", "elbow.ext", 1.469e-6), gen.Effect("valve_delay", "shoulder.flex", 0.045))
    options = {
        "droop_and_delay": gen.GeneratorOptions(duration=60.0, seed=3178743623, effects=effects, substeps=10),
        "offset": gen.GeneratorOptions(
            duration=60.0,
            seed=3783616092,
            substeps=10,
            effects=(gen.Effect("pressure_offset", "shoulder.ext", -9.75844),),
        ),
        "zero_drift": replace(session(20262202), substeps=10),
    }
    return dict(zip(options, gen.generate_many(options.values()), strict=True))


@pytest.fixture(scope="module")
def result(sessions):
    log = sessions["droop_and_delay"]
    return log, diagnose(log, load_robot(gen.ROBOT_DIR), DiagnoseOptions(domain="pneumatics"))


def _found(result, chamber):
    return [f for f in result.findings if f.channel == chamber]


def test_a_restricted_supply_line_is_named_supply_droop_through_a_hose(result):
    # the generator's line feeds a hose (its pressure a state): the hose shape, whose sag is a state
    # of its own, fits it better than the bare line (the flow shape: 29 % of the training error
    # removed, the hose 48 %) and is named, with the held-out error lowered
    _, res = result
    found = _found(res, "elbow.ext")
    assert found and (found[0].kind, found[0].cause) == ("term", "supply_droop"), [f.cause for f in found]
    assert found[0].term.extra.get("shape") == "hose" and found[0].term.extra["tau_s"] > 0
    assert found[0].gain()["reduction"] > 0.2


def test_a_delayed_valve_is_named_with_the_valve_delay_within_two_standard_errors(result):
    log, res = result
    found = _found(res, "shoulder.flex")
    assert found and found[0].cause == "valve_delay", [f.cause for f in found]
    truth = next(e["values"]["delay_s"] for e in log.truth.effects if e["cause"] == "valve_delay")
    delay, se = found[0].term.values[0], found[0].term.parameters[0].stderr
    assert abs(delay - truth) <= 2.0 * se, (delay, truth, se)


def test_the_clean_chambers_give_nothing(result):
    _, res = result
    assert _found(res, "shoulder.ext") == [] and _found(res, "elbow.flex") == []


def test_a_sensor_offset_the_held_out_rows_do_not_confirm_is_not_named_a_supply_sag(sessions):
    # the offset removes most of the validation error (74 % at 20 sub-steps) but its extension raises
    # the held-out error; a supply sag, which a constant offset partly mimics, removes less (48 %): not
    # the cause to name
    log = sessions["offset"]
    res = diagnose(log, load_robot(gen.ROBOT_DIR), DiagnoseOptions(domain="pneumatics", chambers=("shoulder.ext",)))
    (found,) = _found(res, "shoulder.ext")
    assert found.cause == "unexplained", found.cause
    assert found.evidence["stand_in"]["term"] == "supply_droop:shoulder.ext"
    assert found.evidence["declined"]["term"] == "pressure_offset:shoulder.ext"
    assert "held-out error rose" in found.evidence["declined"]["why"]


def test_a_zero_that_drifts_over_the_session_is_not_named_a_sensor_offset(sessions):
    # experiments/pneumatic_oov.py: shoulder.ext's zero drifts by 4.9 kPa over the 60 s; the offsets
    # of the earlier and later training halves differ by 2.5 kPa (z 7: DRIFT_Z), so no constant
    # offset is offered and the structure is left unexplained (named pressure_offset before)
    from experiments.pneumatic_oov import add_shape

    log, chamber, size = add_shape("zero_drift", 20262202, log=sessions["zero_drift"])
    assert chamber == "shoulder.ext" and size == pytest.approx(4.868, abs=1e-3)
    options = DiagnoseOptions(domain="pneumatics", chambers=(chamber,))
    res = diagnose(log.without_truth(), load_robot(gen.ROBOT_DIR), options)
    assert [f.cause for f in _found(res, chamber)] == ["unexplained"]
