"""Off its own simulator, diagnose names what it can and says `unexplained` for what it cannot:
a UR5 (example-robot-data inertias; experiments/dynamics_generator.py, written apart from
diegocal's simulator) whose Coulomb friction switches smoothly through zero velocity got
`torque_lag` on five joints before friction's shape near zero velocity was in the vocabulary."""

from __future__ import annotations

import numpy as np
import pytest

import diegocal.sgp.terms as dynamics_terms
from diegocal.diagnose import DiagnoseOptions, diagnose
from diegocal.diagnose.dynamics import DynamicsAdapter
from diegocal.robot.resolve import robot_for_log
from experiments.dynamics_generator import Session, generate, urdf

pytestmark = pytest.mark.skipif(not urdf("ur5").is_file(), reason="example-robot-data is not installed")


def _diagnose(session: Session):
    log = generate(session)
    return log, diagnose(log, robot_for_log(None, log), DiagnoseOptions(domain="dynamics"))


@pytest.fixture(scope="module")
def smooth():
    return _diagnose(Session(duration=20.0, seed=5, robot_seed=5, coulomb=(0.1, 0.2)))


def test_smooth_friction_is_named_as_friction_never_a_lag(smooth):
    log, d = smooth
    causes = {f.cause for f in d.findings}
    assert causes and causes <= {"stribeck_friction", "unexplained"}, causes
    for f in d.findings:
        if f.cause == "stribeck_friction":  # a smooth transition: below Coulomb near zero velocity
            assert f.term.value("amplitude") < 0
            assert 0.005 < f.term.value("velocity_scale") < 0.05  # tanh(qd / 0.02) ≈ 1 − 2 e^(−2|qd|/0.02)
            assert np.isfinite(f.term.parameters[1].stderr)


def test_without_its_term_the_stand_in_is_refused(monkeypatch):
    """With friction's shape taken out of the vocabulary, the lags that stood in for it are not
    named: the channels are unexplained, their evidence names the stand-in and the flexible
    model's gain (the SGP that would absorb them is not fitted here: it is not what is tested)."""
    monkeypatch.setitem(dynamics_terms.PROPOSE, "stribeck_friction", lambda cause, ctx: [])
    monkeypatch.setattr(DynamicsAdapter, "absorb", lambda self, fitted, channels, train: None)
    _, d = _diagnose(Session(duration=60.0, seed=0, robot_seed=0, coulomb=(0.1, 0.2)))
    causes = [f.cause for f in d.findings]
    assert "torque_lag" not in causes, causes
    stood = [f for f in d.findings if f.cause == "unexplained" and "stand_in" in f.evidence]
    assert stood, causes
    ev = stood[0].evidence
    assert ev["stand_in"]["validation_gain"] < 0.5 * ev["validation_gain"]


def test_a_hidden_effect_beside_smooth_friction_is_named_first():
    log, d = _diagnose(Session(duration=20.0, seed=7, robot_seed=7, coulomb=(0.1, 0.2), hidden="torque_offset"))
    top = d.findings[0]
    assert (top.cause, top.channel) == ("torque_offset", log.truth.effects[0]["channel"])
    assert top.term.value("offset") == pytest.approx(log.truth.effects[0]["scale"], rel=0.1)


def test_a_torque_sensors_gain_is_named_with_its_error():
    """The independent generator's sensor reading 4 % high on one joint (friction included) was
    named a torque offset on the Z1 of a user trial before torque_gain was a cause."""
    log, d = _diagnose(Session(duration=20.0, seed=1, robot_seed=1, smooth_scale=0.0, hidden="torque_gain"))
    hidden = log.truth.effects[0]
    top = d.findings[0]
    assert (top.cause, top.channel) == ("torque_gain", hidden["channel"]), [(f.cause, f.channel) for f in d.findings]
    p = top.term.parameters[0]
    assert abs(p.value - hidden["scale"]) < 2 * p.stderr < 0.1 * hidden["scale"]
    assert top.term.extra["relative"]  # the inertias identified: one joint's gain against the others'


def test_friction_that_grows_with_the_load_is_named_load_friction():
    """Friction in proportion to the joint's load torque (the generator's |τ| tanh(qd/0.02), beside
    smooth friction on every joint) was named a position friction before load_friction was a cause."""
    log, d = _diagnose(Session(duration=20.0, seed=2, robot_seed=2, hidden="load_friction"))
    hidden = log.truth.effects[0]
    top = d.findings[0]
    assert (top.cause, top.channel) == ("load_friction", hidden["channel"]), [(f.cause, f.channel) for f in d.findings]
    assert top.term.value("coefficient") == pytest.approx(hidden["scale"], rel=0.1)
    assert {f.cause for f in d.findings} <= {"load_friction", "stribeck_friction", "unexplained"}


def test_a_hose_pulled_by_the_next_joint_is_unexplained_not_a_spring():
    """A torque on one joint from the next joint's angle (a hose) was named a spring on the joint
    whose angle correlates with the next one's: the flexible model it must match now sees the other
    joints' angles too, and the finding is ``unexplained``, shown against another joint's angle (the
    one whose binned mean predicts the validation blocks best: the puller or one that moves with it)."""
    log, d = _diagnose(Session(duration=60.0, seed=3, robot_seed=3, coulomb=(0.1, 0.2), hidden="hose"))
    hidden = log.truth.effects[0]
    named = [(f.cause, f.channel) for f in d.findings]
    assert {c for c, _ in named} <= {"stribeck_friction", "unexplained"}, named
    (found,) = [f for f in d.findings if f.cause == "unexplained" and f.channel == hidden["channel"]]
    assert found.evidence["variable"].startswith("q.")
    assert found.evidence["variable"] != f"q.{hidden['channel']}"
    assert found.evidence["stand_in"]["validation_gain"] < 0.5 * found.evidence["validation_gain"]


def test_friction_that_drifts_over_the_session_is_said_to_shift_in_time():
    """A friction growing over the session (temperature) is no term of the vocabulary; a user trial
    got "nothing significant" with its joint's held-out error four times the noise. The residual
    times the direction of motion shifts in time, and the diagnosis says so on that joint, where a
    clean session of the same robot says nothing."""
    from diegocal.diagnose.output import diagnosis_dict, shifting_channels

    drift = Session(duration=30.0, seed=3, robot_seed=3, smooth_scale=0.0, hidden="drifting_friction", size=8)
    log, d = _diagnose(drift)
    joint = log.truth.effects[0]["channel"]
    shifting = [c for c, _, _ in shifting_channels(diagnosis_dict(d))]
    assert any(c.endswith(joint) for c in shifting), (joint, shifting, [f.cause for f in d.findings])
    _, clean = _diagnose(Session(duration=30.0, seed=3, robot_seed=3, smooth_scale=0.0))
    assert shifting_channels(diagnosis_dict(clean)) == []
