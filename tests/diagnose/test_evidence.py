"""The evidence curve of a finding: a friction's residual follows the direction of motion, so its
mean over an angle the joint crosses both ways is nothing unless it is taken times sign(qd)."""

import numpy as np

from diegocal.causes import CAUSES
from diegocal.diagnose.evidence import curves
from diegocal.diagnose.types import Residuals


def _friction_in_a_region(seed: int = 0):
    """A joint sweeping 0.5-1.9 rad back and forth, with friction 0.5 · sign(qd) between 1.0 and
    1.4 rad and white noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(6000) * 0.01
    q = 1.2 + 0.7 * np.sin(2 * np.pi * t / 7.0)
    qd = np.gradient(q, t)
    inside = (q > 1.0) & (q < 1.4)
    r = 0.5 * np.sign(qd) * inside + 0.01 * rng.normal(size=t.size)
    return Residuals({"j": r}, {"j": "N·m"}, {"time": t, "q.j": q, "qd.j": qd}), inside


def test_a_friction_is_shown_times_the_sign_of_its_velocity():
    res, inside = _friction_in_a_region()
    shown = np.arange(inside.size) >= 3000
    train = ~shown
    plain = curves(res, None, "j", "q.j", shown, 200, train, 10, None)
    signed = curves(res, None, "j", "q.j", shown, 200, train, 10, None, signed_by="qd")
    assert "signed_by" not in plain and signed["signed_by"] == "qd.j"
    centre = np.array(signed["before"]["centre"], float)
    mean_plain, mean_signed = (np.array(c["before"]["mean"], float) for c in (plain, signed))
    in_region = (centre > 1.05) & (centre < 1.35)
    assert in_region.any() and np.all(np.abs(mean_plain[in_region]) < 0.1)  # averaged away
    assert np.all(mean_signed[in_region] > 0.4)  # the friction's level
    assert np.all(np.abs(mean_signed[(centre < 0.9) | (centre > 1.5)]) < 0.05)
    q = res.variables["q.j"][shown]
    assert signed["reach"] == [q.min(), q.max()]  # the samples' extent, beyond the outer bins' medians
    assert signed["reach"][0] < centre[0] and signed["reach"][1] > centre[-1]
    binned_by_velocity = curves(res, None, "j", "qd.j", shown, 200, train, 10, None, signed_by="qd")
    assert "signed_by" not in binned_by_velocity  # a velocity's own bins show the sign already


def test_the_registry_says_which_causes_follow_the_direction_of_motion():
    signed = {c for c, entry in CAUSES.items() if entry.signed_by}
    assert {"position_friction", "coulomb_friction", "load_friction", "viscous_friction", "stribeck_friction"} <= signed
    assert not {"spring", "torque_offset", "payload", "armature"} & signed


def test_a_motor_that_drives_two_joints_is_signed_by_its_own_velocity():
    """Coupled friction follows the sign of qd_j + ratio · qd_partner (the TX40's wrist motor), not
    of either joint's velocity alone."""
    rng = np.random.default_rng(1)
    t = np.arange(6000) * 0.01
    q, qp = np.sin(2 * np.pi * t / 7.0), np.sin(2 * np.pi * t / 3.1 + 1.0)
    qd, qpd = np.gradient(q, t), np.gradient(qp, t)
    r = 0.5 * np.sign(qd - 2.0 * qpd) + 0.01 * rng.normal(size=t.size)
    res = Residuals({"j": r}, {"j": "N·m"}, {"time": t, "q.j": q, "qd.j": qd, "qd.p": qpd})
    shown = np.arange(t.size) >= 3000
    motor = curves(res, None, "j", "q.j", shown, 200, ~shown, 10, None, signed_by="qd", partner=("p", -2.0))
    alone = curves(res, None, "j", "q.j", shown, 200, ~shown, 10, None, signed_by="qd")
    assert motor["signed_by"] == "qd.j − 2·qd.p"
    assert np.all(np.array(motor["before"]["mean"], float) > 0.45)
    assert np.mean(np.array(alone["before"]["mean"], float)) < 0.4  # its own velocity's sign explains less
    assert CAUSES["coupled_friction"].signed_by == "qd"
