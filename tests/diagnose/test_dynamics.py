"""`diagnose --domain dynamics` on simulated torque logs: each hidden cause (random joint, size 3-10
times the torque noise, random region where it has one) is the top finding, on the right joint,
with a positive held-out gain; clean logs give nothing; two hidden effects are both found; robots
from example-robot-data (UR5, Panda) are among the cases; `predict` uses the extended model.

The simulator's effects are physical shapes of their own (a rotor inertia in the model, a motor's
tanh friction, a low-pass torque sensor), never the candidate terms. The diagnosis never reads
``/truth``; the tests read it to choose sizes and to compare.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from diegocal.cli import app
from diegocal.diagnose import DiagnoseOptions, diagnose
from diegocal.io import load_log, save_log
from diegocal.io.bundle import load_bundle
from diegocal.robot import load_robot
from diegocal.robot.model import BUNDLED_ROBOTS
from diegocal.sgp.bodies import payload_links
from diegocal.sim.dynamics import DynamicsOptions, simulate_dynamics

sys.path.insert(0, str(Path(__file__).parents[1]))
from erd import robot_dir  # noqa: E402

NOISE = 0.01  # N·m, the simulator's default torque noise
runner = CliRunner()


@pytest.fixture(scope="module")
def arm3():
    return load_robot(BUNDLED_ROBOTS / "arm3")


@pytest.fixture(scope="module")
def erd_robots(tmp_path_factory):
    base = tmp_path_factory.mktemp("erd")
    return {name: load_robot(robot_dir(base, name)) for name in ("ur5", "panda")}


def simulate(robot, effects=(), seed=0, duration=20.0, regions=None):
    opts = DynamicsOptions(duration=duration, effects=tuple(effects), noise=NOISE, regions=regions or {})
    return simulate_dynamics(robot, opts, np.random.default_rng(seed))


def hidden(robot, cause, seed, duration=20.0):
    """A log with ``cause`` on a random joint (not the first: its armature and the like are the
    first link's own inertia), size U(3, 10) × noise (a lag sized so that lag·RMS(dτ/dt) is),
    a random region (a fifth of the joint's visited range) for position_friction."""
    rng = np.random.default_rng(1000 + seed)
    j = int(rng.integers(1, robot.n_joints))
    joint = robot.joint_names[j]
    ratio = rng.uniform(3.0, 10.0)
    clean = simulate(robot, seed=seed, duration=duration)  # same trajectory (independent streams)
    regions = {}
    if cause == "torque_lag":
        tau = clean.truth.signals["tau"].data[:, j]
        size = ratio * NOISE / np.sqrt(np.mean(np.gradient(tau, clean.time) ** 2))
    elif cause == "torque_gain":  # sized so that gain_error · RMS(τ) is
        size = ratio * NOISE / np.sqrt(np.mean(clean.truth.signals["tau"].data[:, j] ** 2))
    elif cause == "transmission_backlash":  # sized by the joint's torque change per rad of a small play
        small = simulate(robot, [f"{cause}:{joint}=0.005"], seed, duration).truth.signals["tau"].data[:, j]
        change = np.sqrt(np.mean((small - clean.truth.signals["tau"].data[:, j]) ** 2)) / 0.005
        size = min(ratio * NOISE / change, 0.1)
    else:
        size = ratio * NOISE
    if cause == "position_friction":
        q = clean.stream("q").data[:, j]
        lo, hi = np.quantile(q, [0.05, 0.95])
        width = 0.2 * (hi - lo)
        low = rng.uniform(lo, hi - width)
        regions = {joint: (float(low), float(low + width))}
    log = simulate(robot, [f"{cause}:{joint}={size:.6g}"], seed, duration, regions)
    return log, joint, regions.get(joint)


def run(log, robot, friction=("viscous", "coulomb")):
    return diagnose(log, robot, DiagnoseOptions(domain="dynamics", friction=friction))


def assert_named(d, cause, joint, region=None, tol=0.15):
    assert d.findings, "nothing found"
    top = d.findings[0]
    labels = [f.term.label for f in d.findings]
    assert (top.kind, top.cause) == ("term", cause), labels
    if cause == "coupled_friction":  # one motor on a joint and the one before it
        assert joint in (top.channel, top.term.extra["partner"]), labels
    else:
        assert top.channel == joint, labels
    gain = top.gain()
    assert gain["rmse_after"] < gain["rmse_before"], gain
    if region is not None:
        r = top.term.region
        assert r.variable == f"q.{joint}"
        width = region[1] - region[0]
        assert abs(r.low - region[0]) < tol * 2 * width + 0.05, (r, region)
        assert abs(r.high - region[1]) < tol * 2 * width + 0.05, (r, region)
    return top


# ----------------------------------------------------------------------------- one cause each
@pytest.mark.parametrize(
    "cause,seed",
    [
        ("torque_offset", 0),
        ("spring", 1),
        ("armature", 2),
        ("torque_lag", 3),
        ("torque_gain", 6),
        ("transmission_backlash", 7),
        ("position_friction", 4),
        ("coupled_friction", 5),
    ],
)
def test_arm3_each_hidden_cause_is_the_top_finding(arm3, cause, seed):
    log, joint, region = hidden(arm3, cause, seed)
    d = run(log, arm3)
    top = assert_named(d, cause, joint, region)
    assert top.evidence["validation_gain"] > 0.05


@pytest.mark.parametrize("cause,baseline", [("coulomb_friction", ("viscous",)), ("viscous_friction", ("coulomb",))])
def test_friction_a_baseline_lacks_is_found_on_every_joint(arm3, cause, baseline):
    """The simulated robot has both frictions on every joint; a baseline without one of them gets
    it back, joint by joint (each a finding with a held-out gain)."""
    d = run(simulate(arm3, seed=11), arm3, friction=baseline)
    assert {f.cause for f in d.findings} == {cause}
    assert {f.channel for f in d.findings} == set(arm3.joint_names)
    assert all(f.gain()["reduction"] > 0.1 for f in d.findings)


def test_a_coulomb_friction_is_not_named_by_a_position_friction_over_most_of_the_range(arm3):
    """A Coulomb friction on joint3 (4.5 × the noise; the naming bench's seed 1180248167): a
    position friction over most of joint3's range, tested with joint1's as one cause, fits the
    validation data a tenth of a percent better, with a viscous part of its own; the simpler cause
    that does as well is named (selection.SIMPLER_SHARE), and it does better held out."""
    opts = DynamicsOptions(duration=30.0, effects=("coulomb_friction:joint3=0.0452634",), noise=NOISE, coulomb=0.0)
    log = simulate_dynamics(arm3, opts, np.random.default_rng(1180248167))  # Coulomb on joint3 only
    d = run(log, arm3, friction=("viscous",))
    top = assert_named(d, "coulomb_friction", "joint3")
    assert [f.term.label for f in d.findings] == [top.term.label]
    assert top.gain()["reduction"] > 0.55, top.gain()
    assert abs(top.term.values[0] - 0.0452634) < 2 * top.term.stderrs[0], top.term


def test_a_friction_region_that_ends_where_the_training_data_end_is_closed_when_validation_says_so(arm3):
    """A position friction on joint2 over −0.77..−0.23 rad (the naming bench's seed 3227015462):
    the training blocks' lowest angle, −0.73 rad, is the region's lower edge, and the validation
    blocks go lower, where there is no friction. The region open to the joint's limit and the one
    closed at the data's end fit the training data alike; both are tested, and the closed one is
    named (the open one cost the validation blocks 26 % and was no finding)."""
    region = (-0.7660298694994456, -0.22768221503689823)
    opts = DynamicsOptions(duration=30.0, effects=("position_friction:joint2=0.0526335",), noise=NOISE,
                           regions={"joint2": region})
    log = simulate_dynamics(arm3, opts, np.random.default_rng(3227015462))
    d = run(log, arm3)
    top = assert_named(d, "position_friction", "joint2")
    assert top.term.region.low > arm3.lower[1] + 1.0, top.term.region  # closed, not open to the limit
    assert abs(top.term.region.low - region[0]) < 0.05 and abs(top.term.region.high - region[1]) < 0.05
    assert top.gain()["reduction"] > 0.5, top.gain()
    values, ses = top.term.values, top.term.stderrs
    assert np.all(np.abs(values - [0.0526335, 0.02598211]) < 2 * ses), (values, ses)


@pytest.mark.parametrize(
    "name,cause,seed",
    [
        ("ur5", "position_friction", 0),
        ("ur5", "torque_offset", 1),
        ("panda", "coupled_friction", 2),
        ("panda", "armature", 3),
    ],
)
def test_robots_from_example_robot_data(erd_robots, name, cause, seed):
    robot = erd_robots[name]
    log, joint, region = hidden(robot, cause, seed, duration=15.0)
    assert_named(run(log, robot), cause, joint, region)


# ----------------------------------------------------------------------------- clean and two effects
@pytest.mark.parametrize("seed", [21, 22, 23])
def test_clean_arm3_logs_give_no_findings(arm3, seed):
    d = run(simulate(arm3, seed=seed), arm3)
    assert d.findings == (), [f.term.label for f in d.findings]
    u = d.units[0]
    assert u.extended_model == u.baseline_model
    assert u.fitted.gp is None and u.fitted.model.options.kind == "pr"  # no non-parametric part was fitted


@pytest.mark.parametrize("name", ["ur5", "panda"])
def test_clean_erd_logs_give_no_findings(erd_robots, name):
    robot = erd_robots[name]
    d = run(simulate(robot, seed=31, duration=15.0), robot)
    assert d.findings == (), [f.term.label for f in d.findings]


def test_two_hidden_effects_are_both_found(erd_robots):
    robot = erd_robots["ur5"]
    effects = ["position_friction:shoulder_lift_joint=0.05", "torque_lag:wrist_1_joint=0.01"]
    log = simulate(robot, effects, seed=1, duration=30.0)
    d = run(log, robot)
    named = {(f.cause, f.channel) for f in d.findings if f.kind == "term"}
    assert ("position_friction", "shoulder_lift_joint") in named, named
    assert ("torque_lag", "wrist_1_joint") in named, named
    lag = next(f.term for f in d.findings if f.cause == "torque_lag")
    assert lag.value("lag") == pytest.approx(0.01, rel=0.2)
    u = d.units[0]
    assert u.extended_score.pooled_rmse() < 0.8 * u.baseline_score.pooled_rmse()


def test_a_payload_is_absorbed_by_the_identified_rigid_body(arm3):
    """A point mass on a link only changes that link's inertial parameters, which the baseline
    identifies: no model error, no finding, held-out RMSE at the noise."""
    log = simulate(arm3, ["payload=0.5"], seed=7)
    d = run(log, arm3)
    assert d.findings == ()
    assert d.units[0].baseline_score.pooled_rmse() < 1.2 * NOISE


# ----------------------------------------------------------------------------- nominal inertias: a payload
def hidden_payload(robot, seed, duration=30.0):
    """A log with a point mass on a random moving link (not the first joint's), sized so that its
    torque's RMS on the joint it loads most is U(3, 10) × noise (effects scale with the mass: a
    1-kg twin of the log on the same trajectory gives the scale)."""
    rng = np.random.default_rng(2000 + seed)
    link = rng.choice(payload_links(robot)[1:])
    ratio = rng.uniform(3.0, 10.0)
    clean = simulate(robot, seed=seed, duration=duration)
    unit = simulate(robot, [f"payload:{link}=1"], seed, duration)
    diff = unit.truth.signals["tau"].data - clean.truth.signals["tau"].data
    mass = ratio * NOISE / np.sqrt(np.mean(diff**2, axis=0)).max()
    return simulate(robot, [f"payload:{link}={mass:.6g}"], seed, duration), str(link)


def run_nominal(log, robot):
    return diagnose(log, robot, DiagnoseOptions(domain="dynamics", inertia="nominal"))


def assert_payload_named(d, log, robot, link):
    """The top finding is the payload on ``link`` with a held-out gain; its first moments m·c are
    within 10 % of the truth's largest or 4 standard errors where identified (a moment along the
    axis of every earlier joint leaves no torque: NaN std) and its mass within 10 % where the mass
    is identified (a link whose origin lies on every earlier joint's axis shows only m·c)."""
    import pinocchio as pin

    assert d.findings, "nothing found"
    top = d.findings[0]
    assert (top.cause, top.channel) == ("payload", link), [f.term.label for f in d.findings]
    gain = top.gain()
    assert gain["rmse_after"] < 0.8 * gain["rmse_before"], gain
    (truth,) = log.truth.effects
    frame = next(f for f in robot.model.frames if f.name == link and f.type == pin.FrameType.BODY)
    mass = truth["values"]["mass"]
    mc = mass * frame.placement.act(np.array([truth["values"][k] for k in "xyz"]))
    par = {p.name: p for p in top.term.parameters}
    got = np.array([par[k].value for k in ("mc_x", "mc_y", "mc_z")])
    se = np.array([par[k].stderr for k in ("mc_x", "mc_y", "mc_z")])
    seen = np.isfinite(se)  # a moment along the axis of every joint before it leaves no torque
    assert seen.sum() >= 2, se
    ok = np.abs(got - mc) < np.maximum(0.1 * np.abs(mc).max(), 4 * se)
    assert ok[seen].all(), (got, mc, se)
    m = top.term.parameters[0]
    if np.isfinite(m.stderr):  # else its column lies in the others' span: any value fits
        assert m.value == pytest.approx(mass, rel=0.1)
    return top


@pytest.mark.parametrize("seed", [100, 101])  # link3 (mass identified), link2 (moments only)
def test_a_payload_is_named_against_nominal_inertias(arm3, seed):
    log, link = hidden_payload(arm3, seed)
    d = run_nominal(log, arm3)
    assert_payload_named(d, log, arm3, link)
    assert d.units[0].extended_score.pooled_rmse() < 1.2 * NOISE


def test_a_payload_on_a_ur5_link_is_named_against_nominal_inertias(erd_robots):
    robot = erd_robots["ur5"]
    log, link = hidden_payload(robot, 100, duration=15.0)
    assert_payload_named(run_nominal(log, robot), log, robot, link)


@pytest.mark.parametrize("seed", [21, 22])
def test_clean_arm3_logs_give_no_findings_against_nominal_inertias(arm3, seed):
    """The URDF is the simulated rigid body: the baseline fits the simulator's friction, nothing
    is left (and the baseline is at the noise)."""
    d = run_nominal(simulate(arm3, seed=seed), arm3)
    assert d.findings == (), [f.term.label for f in d.findings]
    assert d.units[0].baseline_score.pooled_rmse() < 1.2 * NOISE


def test_cli_diagnose_nominal_then_predict_with_the_extended_model(arm3, tmp_path):
    log = simulate(arm3, ["payload:link3=0.05"], seed=5)
    path = tmp_path / "run.h5"
    save_log(log, path)
    args = ["diagnose", str(path), "--domain", "dynamics", "--inertia", "nominal", "--robot", str(arm3.directory)]
    res = runner.invoke(app, args)
    assert res.exit_code == 0, res.output
    extended = tmp_path / "run.extended.sgp"
    bundle = load_bundle(extended)
    assert bundle.kind == "dynamics"
    assert bundle.data["options"]["inertia"] == "nominal"
    terms = bundle.data["terms"]
    assert [(t["cause"], t["channel"]) for t in terms] == [("payload", "link3")]
    assert terms[0]["parameters"]["mass"]["value"] == pytest.approx(0.05, rel=0.05)
    out = tmp_path / "pred.h5"
    res = runner.invoke(app, ["predict", str(extended), str(path), "-o", str(out)])
    assert res.exit_code == 0, res.output
    err = load_log(out).stream("tau").data - log.stream("tau").data
    rmse = np.sqrt(np.mean(err**2, axis=0))
    assert (rmse < 1.5 * NOISE).all(), rmse  # nominal rigid body + friction + the payload


# ----------------------------------------------------------------------------- the command line
def test_cli_diagnose_then_predict_with_the_extended_model(arm3, tmp_path):
    log = simulate(arm3, ["torque_offset:joint2=0.05"], seed=5)
    path = tmp_path / "run.h5"
    save_log(log, path)
    res = runner.invoke(app, ["diagnose", str(path), "--domain", "dynamics", "--robot", str(arm3.directory)])
    assert res.exit_code == 0, res.output
    extended = tmp_path / "run.extended.sgp"
    bundle = load_bundle(extended)
    assert bundle.kind == "dynamics"
    terms = bundle.data["terms"]
    assert [(t["cause"], t["channel"]) for t in terms] == [("torque_offset", "joint2")]
    assert terms[0]["parameters"]["offset"]["value"] == pytest.approx(0.05, abs=0.005)
    out = tmp_path / "pred.h5"
    res = runner.invoke(app, ["predict", str(extended), str(path), "-o", str(out)])
    assert res.exit_code == 0, res.output
    pred = load_log(out)
    err = pred.stream("tau").data - log.stream("tau").data
    rmse = np.sqrt(np.mean(err**2, axis=0))
    assert (rmse < 1.5 * NOISE).all(), rmse  # the offset is predicted (it alone is 5 × noise)
    # the diagnosis.yaml stands for its extended model
    res = runner.invoke(app, ["predict", str(tmp_path / "run.diagnosis.yaml"), str(path), "-o", str(out)])
    assert res.exit_code == 0, res.output


# ----------------------------------------------------------------------------- unexplained: the SGP absorbs it
def with_bump(robot, seed, duration=30.0):
    """A log with a torque that no term of the vocabulary expresses, added to the simulated one
    here (not a simulator effect): a smooth bump in the angle of a random joint (not the first),
    a Gaussian of width a tenth of its visited range centred in its middle 60 %, independent of the
    velocity (a position_friction needs sign(qd), a spring is linear), RMS U(3, 10) × noise."""
    from diegocal.io import make_stream

    log = simulate(robot, seed=seed, duration=duration)
    rng = np.random.default_rng([seed, 7])
    j = int(rng.integers(1, robot.n_joints))
    q = log.stream("q").data[:, j]
    lo, hi = np.quantile(q, [0.2, 0.8])
    width = 0.1 * float(np.subtract(*np.quantile(q, [0.95, 0.05])))
    bump = np.exp(-0.5 * ((q - rng.uniform(lo, hi)) / width) ** 2)
    bump *= rng.uniform(3.0, 10.0) * NOISE / np.sqrt(np.mean(bump**2))
    tau = log.stream("tau").data.copy()
    tau[:, j] += bump
    return log.with_streams(tau=make_stream(log.stream("tau").names, tau)), robot.joint_names[j]


def test_the_absorbing_sgp_s_convergence_is_said(arm3, monkeypatch):
    """The non-parametric fit that absorbs what stays unexplained is a kept fit too: what it left
    at a cap (here made to say so) is in the diagnosis's ``unconverged``, the baseline's not."""
    from diegocal.diagnose.dynamics import DynamicsAdapter

    monkeypatch.setattr(
        DynamicsAdapter,
        "unconverged",
        staticmethod(lambda fitted: ("stopped",) if fitted.model.options.kind == "sgp" else ()),
    )
    log, joint = with_bump(arm3, seed=0)
    unit = diagnose(log, arm3, DiagnoseOptions(domain="dynamics")).units[0]
    assert [f.channel for f in unit.findings if f.kind == "unexplained"] == [joint]
    assert unit.unconverged == ("with the non-parametric part: stopped",)


def test_cli_unexplained_structure_is_absorbed_by_the_sgp(arm3, tmp_path):
    """A bump no term expresses: reported ``unexplained`` on its joint; the extended model is an
    SGP whose GP absorbs it (held-out RMSE on the joint at the noise, against 5-9 × for the
    baseline), a bundle `predict` uses."""
    log, joint = with_bump(arm3, seed=0)
    path = tmp_path / "run.h5"
    save_log(log, path)
    res = runner.invoke(app, ["diagnose", str(path), "--domain", "dynamics", "--robot", str(arm3.directory)])
    assert res.exit_code == 0, res.output
    from diegocal.io import load_yaml

    d = load_yaml(tmp_path / "run.diagnosis.yaml")
    found = [f for f in d["findings"] if f["kind"] == "unexplained"]
    assert [f["channel"] for f in found] == [joint], [(f["cause"], f["channel"]) for f in d["findings"]]
    gain = found[0]["gain"]
    assert gain["rmse_after"] < 0.5 * gain["rmse_before"], gain
    assert found[0]["evidence"]["nonparametric"]["kept"] is True
    curves = found[0]["evidence"]["curves"]  # the evidence plot: binned residual before and after
    assert max(map(abs, filter(None, curves["after"]["mean"]))) < 0.5 * max(
        map(abs, filter(None, curves["before"]["mean"]))
    )
    base, ext = d["baseline"]["heldout_rmse"][joint], d["extended"]["heldout_rmse"][joint]
    assert base > 3 * NOISE and ext < 1.5 * NOISE, (base, ext)
    assert "gp[" in d["extended"]["model"] and joint in d["extended"]["model"].split("gp[")[1]
    extended = tmp_path / "run.extended.sgp"
    bundle = load_bundle(extended)
    assert bundle.kind == "dynamics" and bundle.data["options"]["kind"] == "sgp"
    # saved fitted on the whole log (a user trial: the training blocks' GP predicted a new session badly)
    assert bundle.data["n_samples"] == log.n_samples and "whole log" in bundle.data["meta"]["fitted_on"]
    out = tmp_path / "pred.h5"
    res = runner.invoke(app, ["predict", str(extended), str(path), "-o", str(out)])
    assert res.exit_code == 0, res.output
    err = load_log(out).stream("tau").data - log.stream("tau").data
    assert np.sqrt(np.mean(err**2, axis=0)).max() < 1.5 * NOISE


# ----------------------------------------------------------------------------- naming rates (slow)
@pytest.mark.slow
def test_unexplained_structure_rate_over_ten_seeds(arm3):
    """Ten random bumps (:func:`with_bump`) on 30-s logs: at least 8 are reported ``unexplained``
    on their joint with the extended model's held-out RMSE there under half the baseline's
    (measured 9/10 on seeds 0-9; the miss, 4.4 × noise, gives no finding)."""
    ok = 0
    for seed in range(10):
        log, joint = with_bump(arm3, seed)
        d = run(log, arm3)
        u = d.units[0]
        i = u.baseline_score.channels.index(joint)
        flagged = any(f.kind == "unexplained" and f.channel == joint for f in d.findings)
        ok += flagged and u.extended_score.rmse[i] < 0.5 * u.baseline_score.rmse[i]
    assert ok >= 8, ok


@pytest.mark.slow
@pytest.mark.parametrize(
    "cause",
    [
        "torque_offset",
        "spring",
        "armature",
        "torque_lag",
        "torque_gain",
        "transmission_backlash",
        "position_friction",
        "coupled_friction",
    ],
)
def test_naming_rate_over_ten_seeds(arm3, cause):
    """Ten random draws per cause on 30-s logs (the fast tests use 20 s; a position_friction of 3 ×
    noise in a fifth of the range is then named 8 times in 10 on seeds 100-109: the validation
    blocks see the region too rarely for the out-of-sample test): every effect that leaves a model
    error (the baseline's held-out RMSE on its joint above 1.1 × noise; an armature of arm3's
    joint2 lies in the rigid body's span and is absorbed) is named at least 9 times in 10."""
    named, errors = 0, 0
    for seed in range(100, 110):
        log, joint, region = hidden(arm3, cause, seed, duration=30.0)
        d = run(log, arm3)
        base = d.units[0].baseline_score
        if base.rmse[base.channels.index(joint)] < 1.1 * NOISE:
            assert not d.findings or d.findings[0].gain()["reduction"] > 0  # absorbed: nothing to name
            continue
        errors += 1
        try:
            assert_named(d, cause, joint, region)
            named += 1
        except AssertionError:
            pass
    assert errors >= 5 and named >= 0.9 * errors, (named, errors)


@pytest.mark.slow
def test_gain_naming_rate_over_ten_seeds(erd_robots):
    """A torque sensor's gain error on a random UR5 joint (gain · RMS τ U(3, 10) × noise, 30-s
    logs): named on its joint with the gain error within 3 SE, 10 of 10 on seeds 100-109. With the
    inertial parameters identified, a common scale of every joint's torque is theirs, so a gain is
    one joint's against the others', and its candidate is judged on every joint's residual: judged
    on its own joint's, arm3's seed 107 had its joint3 gain named on joint2 beside two more gains."""
    ur5, named = erd_robots["ur5"], 0
    for seed in range(100, 110):
        log, joint, _ = hidden(ur5, "torque_gain", seed, duration=30.0)
        top = run(log, ur5).findings[0]
        truth = log.truth.effects[0]["values"]["gain_error"]
        p = top.term.parameters[0]
        named += (top.cause, top.channel) == ("torque_gain", joint) and abs(p.value - truth) < 3 * p.stderr
    assert named >= 9, named


@pytest.mark.slow
def test_false_alarms_over_twenty_clean_logs(arm3):
    alarms = sum(bool(run(simulate(arm3, seed=200 + s, duration=30.0), arm3).findings) for s in range(20))
    assert alarms <= 1


@pytest.mark.slow
def test_payload_naming_rate_against_nominal_inertias(arm3):
    """Ten random payloads (random link of joints 2-3, torque U(3, 10) × noise) on 30-s logs: all
    ten named with their moments (measured 10/10 on seeds 100-109), clean logs give nothing."""
    named = 0
    for seed in range(100, 110):
        log, link = hidden_payload(arm3, seed)
        try:
            assert_payload_named(run_nominal(log, arm3), log, arm3, link)
            named += 1
        except AssertionError:
            pass
    assert named >= 9, named
    alarms = sum(bool(run_nominal(simulate(arm3, seed=200 + s, duration=30.0), arm3).findings) for s in range(10))
    assert alarms <= 1
