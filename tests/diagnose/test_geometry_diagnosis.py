"""Link geometry named by ``diagnose --domain kinematics`` on static-pose logs (issue #34), against
the truth of a generator written apart from the estimator (experiments/static_geometry_generator.py:
the Pinocchio model's joint placements perturbed directly). The diagnosis never reads the truth;
these tests read its noise floor (``/truth`` markers_floor: the true model at the angles the
encoders give) to judge the held-out error."""

import numpy as np
import pytest

from diegocal.diagnose import DiagnoseOptions, diagnose
from diegocal.diagnose.geometry import per_joint
from diegocal.diagnose.stats import out_of_sample_test
from diegocal.robot import load_robot

gen = pytest.importorskip("experiments.static_geometry_generator")
if not (gen.SHARE / gen.ROBOTS["panda"][0]).is_file():
    pytest.skip("example-robot-data is not installed", allow_module_level=True)

OPTIONS = DiagnoseOptions(domain="kinematics")


def _floor(log, held: np.ndarray) -> float:
    """RMSE (3-D) on the held-out poses of the readings against the true model at the encoders' angles."""
    e = (log.stream("markers").data - log.truth.signals["markers_floor"].data)[held]
    return float(np.sqrt(np.mean(np.sum(e**2, axis=-1))))


@pytest.fixture(scope="module")
def panda(tmp_path_factory):
    out = tmp_path_factory.mktemp("panda")
    d, log = gen.simulate(out, gen.Session("panda", 60, 1, seed=3))
    return log, diagnose(log, load_robot(d), OPTIONS)


def test_link_geometry_is_named_once_with_its_identifiable_set(panda):
    """One finding, the chain's geometry: its 7 joints' 42 parameters, 31 identifiable in all
    (frame, tool point, encoders' zeros and geometry: the 4R rule, 4·7 + 6 − 3), the rest dropped
    with a reason, a finite condition number; the per-joint terms are those calib.yaml carries."""
    _, diag = panda
    assert [f.cause for f in diag.findings] == ["joint_geometry"]
    term = diag.findings[0].term
    joints = [f"panda_joint{i}" for i in range(1, 8)]
    assert term.extra["joints"] == joints and term.channel == "+".join(joints)
    assert len(term.parameters) == 42
    assert term.extra["identifiable"]["count"] == 31
    dropped = term.extra["dropped"]
    assert len(dropped) == term.extra["identifiable"]["of"] - 31
    assert all(d["reason"] for d in dropped)
    assert 1.0 < term.extra["condition"] < 1e4
    se = term.stderrs
    kept = set(term.extra["identifiable"]["geometry"])
    assert {p.name for p, s in zip(term.parameters, se, strict=True) if np.isfinite(s)} == kept
    assert [t.channel for t in per_joint(term)] == joints


def test_held_out_error_falls_to_the_noise_floor(panda):
    """STAC alone is several times the noise floor on the held-out poses (the URDF's geometry is
    wrong); the extended model is within 1.3 x the floor, and the finding's gain says so."""
    log, diag = panda
    held = diag.blocks.mask("heldout")
    floor = _floor(log, held)
    unit = diag.units[0]
    i = unit.baseline_score.channels.index("tool0")
    assert unit.baseline_score.rmse[i] > 4.0 * floor
    assert unit.extended_score.rmse[i] < 1.3 * floor
    gain = diag.findings[0].gain()
    assert gain["rmse_after"] == pytest.approx(unit.extended_score.rmse[i])
    assert gain["reduction"] > 0.75


def test_nothing_is_named_on_a_static_log_without_geometry_error(tmp_path):
    """The same session with the URDF's geometry exact: no finding (a false alarm would be one)."""
    d, log = gen.simulate(tmp_path, gen.Session("panda", 60, 1, seed=3, link_mm=0.0, axis_deg=0.0))
    diag = diagnose(log, load_robot(d), OPTIONS)
    assert diag.findings == ()
    unit = diag.units[0]
    i = unit.baseline_score.channels.index("tool0")
    assert unit.baseline_score.rmse[i] < 1.3 * _floor(log, diag.blocks.mask("heldout"))


def test_mis_paired_poses_are_a_fault_and_the_geometry_still_named(tmp_path):
    """Four poses filed with another pose's markers: one ``marker_outliers`` fault listing exactly
    those poses (STAC and the geometry fit would write them off in their own fits, leaving their
    readings in every residual and in the held-out score), written off, and the geometry named as
    on the clean-paired session, its held-out error near the noise floor of the clean poses."""
    session = gen.Session("panda", 60, 1, seed=5, hardware_seed=5, wrong=4)
    d, log = gen.simulate(tmp_path, session)
    diag = diagnose(log, load_robot(d), OPTIONS)
    wrong = np.asarray(log.truth.params["wrong_poses"])
    assert sorted(f.cause for f in diag.findings) == ["joint_geometry", "marker_outliers"]
    (fault,) = [f for f in diag.findings if f.kind == "fault"]
    diagnosed = diag.blocks.mask("train") | diag.blocks.mask("validation") | diag.blocks.mask("heldout")
    assert fault.term.extra["poses"] == wrong[diagnosed[wrong]].tolist()
    assert fault.term.extra["frames"] == {"tool0": wrong.tolist()}  # one sample per pose
    assert fault.gain()["reduction"] > 0.5
    (found,) = [f for f in diag.findings if f.cause == "joint_geometry"]
    assert found.term.extra["written_off"] == []  # nothing left for the geometry fit to write off
    held = diag.blocks.mask("heldout")
    held[wrong] = False
    unit = diag.units[0]
    i = unit.extended_score.channels.index("tool0")
    assert unit.extended_score.n_samples[i] == held.sum()  # the foreign poses are out of the score
    assert unit.extended_score.rmse[i] < 1.5 * _floor(log, held)


def test_a_few_independent_poses_are_testable():
    """Validation runs of 6 samples each (a static-pose log's poses): the out-of-sample test cuts
    them into sub-blocks shorter than MIN_CLUSTER and tests; before, fewer than three sub-blocks
    gave t = 0 whatever the error (the Show step's threshold was 477 at one degree of freedom)."""
    rng = np.random.default_rng(0)
    mask = np.zeros(60, bool)
    mask[24:30] = mask[54:60] = True
    idx = np.flatnonzero(mask)
    a = rng.normal(size=idx.size)
    strong = out_of_sample_test(a + 0.1 * rng.normal(size=idx.size), a, idx, mask)
    assert strong.df >= 3 and strong.t > 10
    null = out_of_sample_test(rng.normal(size=idx.size), a, idx, mask)
    assert null.df == strong.df and abs(null.t) < 5


@pytest.mark.parametrize("seed, hardware", [(5, 5), (200, 200)])
def test_a_chance_pass_on_a_few_poses_is_declined_not_named(tmp_path, seed, hardware):
    """Clean static logs whose validation test passed by chance on a dozen poses (a backlash whose
    held-out error rose, a pot nonlinearity 1 SE from zero; both named before the engine declined
    such terms): no finding."""
    session = gen.Session("panda", 60, 1, seed=seed, hardware_seed=hardware, link_mm=0.0, axis_deg=0.0)
    d, log = gen.simulate(tmp_path, session)
    assert diagnose(log, load_robot(d), OPTIONS).findings == ()
