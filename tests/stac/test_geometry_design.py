"""`diegocal poses` (issue #34): chosen static poses beat random ones of the same count, in the
predicted uncertainty of the parameters (D-optimal) and of the markers' predictions (I-optimal,
the default), and in a calibration fitted from them."""

import numpy as np
import pytest
from typer.testing import CliRunner

from diegocal.cli import app
from diegocal.errors import FitError
from diegocal.io import Log, load_log, make_stream, save_log
from diegocal.robot import load_robot
from diegocal.stac.calibration import Calibration
from diegocal.stac.geometry import calibrate_geometry
from diegocal.stac.geometry_design import pose_design, select_poses
from diegocal.stac.predict import predict

gen = pytest.importorskip("experiments.static_geometry_generator")
if not (gen.SHARE / gen.ROBOTS["panda"][0]).is_file():
    pytest.skip("example-robot-data is not installed", allow_module_level=True)

runner = CliRunner()
N = 30


@pytest.fixture(scope="module")
def panda(tmp_path_factory):
    out = tmp_path_factory.mktemp("design")
    session = gen.Session("panda", N, 1, seed=21, hardware_seed=21)
    d, _ = gen.simulate(out, session)
    robot = load_robot(d)
    candidates = gen.candidate_poses(session, 200, seed=5)
    design = pose_design(robot, Calibration.nominal(robot), candidates)
    return out, session, robot, candidates, design, select_poses(design, N)


def test_d_optimal_poses_beat_random_ones_on_parameter_uncertainty(panda):
    _, _, _, _, design, _ = panda
    chosen = select_poses(design, N, criterion="D")
    assert len(design.names) == 31 and len(set(chosen.tolist())) == N
    rng = np.random.default_rng(0)
    draws = [rng.choice(200, N, replace=False) for _ in range(10)]
    assert design.log_det(chosen) > max(design.log_det(d) for d in draws)
    assert design.stderr(chosen).mean() < min(design.stderr(d).mean() for d in draws)


def test_i_optimal_poses_predict_the_markers_best(panda):
    _, _, _, _, design, chosen = panda
    assert len(set(chosen.tolist())) == N
    rng = np.random.default_rng(0)
    random = [design.prediction_variance(rng.choice(200, N, replace=False)) for _ in range(10)]
    mine = design.prediction_variance(chosen)
    assert mine < 0.75 * min(random)
    # the criterion's own optimum: no worse than D-optimal's, nor than the greedy pass alone
    assert mine <= design.prediction_variance(select_poses(design, N, criterion="D"))
    assert mine <= design.prediction_variance(select_poses(design, N, exchange=False))


def test_the_first_poses_of_the_list_are_a_good_choice_themselves(panda):
    _, _, _, _, design, chosen = panda
    rng = np.random.default_rng(2)
    random = [design.prediction_variance(rng.choice(200, 20, replace=False)) for _ in range(10)]
    assert design.prediction_variance(chosen[:20]) < min(random)


def test_the_noise_model_weighs_the_poses(panda):
    _, _, robot, candidates, design, _ = panda
    weighed = pose_design(robot, Calibration.nominal(robot), candidates, sigma_markers=3e-4, sigma_pots=3e-3)
    assert weighed.names == design.names
    # pot noise propagated through the arm adds to every pose's covariance: less information
    assert weighed.log_det(np.arange(200)) < design.log_det(np.arange(200))
    assert weighed.prediction_variance(select_poses(weighed, N)) < weighed.prediction_variance(np.arange(N))


def test_an_unknown_criterion_is_refused(panda):
    with pytest.raises(FitError, match="unknown pose criterion 'A'"):
        select_poses(panda[4], 5, criterion="A")


def test_a_calibration_from_the_chosen_poses_beats_random_ones_on_held_out_poses(panda):
    out, session, robot, candidates, _, chosen = panda
    _, test = gen.simulate(out, gen.Session("panda", 40, 1, seed=121, hardware_seed=21))
    x = test.stream("markers").data
    floor = np.linalg.norm(test.truth.signals["markers_floor"].data - x, axis=-1).mean()

    def held_out(index) -> float:
        _, log = gen.simulate(out, session, q=candidates[index])  # the same noise draw for every set
        cal = calibrate_geometry(log, robot).calibration
        return np.linalg.norm(predict(test, robot, cal, ("pots",), ("markers",)).markers - x, axis=-1).mean() / floor

    rng = np.random.default_rng(1)
    random = [held_out(rng.choice(200, N, replace=False)) for _ in range(3)]
    mine = held_out(chosen)
    assert mine < 1.25 and mine < np.mean(random)


def test_recorded_poses_are_completed(panda):
    _, _, _, _, design, chosen = panda
    for criterion in ("I", "D"):
        more = select_poses(design, 5, recorded=chosen[:25], criterion=criterion)
        assert len(set(more.tolist())) == 5 and not set(more.tolist()) & set(chosen[:25].tolist())


def test_cli_poses(panda, tmp_path):
    out, _, robot, candidates, _, _ = panda
    names = list(robot.joint_names)
    log = Log(np.arange(200.0), {"q": make_stream(names, candidates)}, robot=str(robot.directory), rate_hz=1.0)
    save_log(log, tmp_path / "cand.h5")
    res = runner.invoke(app, ["poses", str(tmp_path / "cand.h5"), "-n", "12", "-o", str(tmp_path / "next.h5")])
    assert res.exit_code == 0, res.output
    assert "I-optimal" in res.output
    chosen = load_log(tmp_path / "next.h5").stream("q").data
    assert chosen.shape == (12, 7) and all(any(np.allclose(c, k) for k in candidates) for c in chosen)
    res = runner.invoke(
        app, ["poses", str(tmp_path / "cand.h5"), "-n", "12", "--criterion", "d", "-o", str(tmp_path / "d.h5")]
    )
    assert res.exit_code == 0 and "D-optimal" in res.output, res.output
    res = runner.invoke(app, ["poses", str(tmp_path / "cand.h5"), "--criterion", "A", "-o", str(tmp_path / "a.h5")])
    assert res.exit_code == 2 and "'A' is not one of I, D" in res.output
    res = runner.invoke(app, ["poses", str(tmp_path / "cand.h5"), "-n", "500", "-o", str(tmp_path / "x.h5")])
    assert res.exit_code == 1 and "cannot choose 500 poses from 200" in res.output and "Traceback" not in res.output
