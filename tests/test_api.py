"""The library as a user scripts it (a user trial of diegocal.api): scikit-learn's parameter
protocol, one DiegocalError for bad options and unfitted estimators, a failed refit that leaves
the last fit as it was, and the command line's bounds on a library call too."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

import diegocal.api as dc
from diegocal.diagnose import DiagnoseOptions
from diegocal.errors import DiegocalError, FitError, InputFileError, NotFittedError, OptionError, UnknownNameError
from diegocal.sgp.model import SGPOptions

SAMPLE = Path(__file__).resolve().parents[1] / "sample_data"


def test_estimators_give_and_take_their_parameters():
    sklearn = pytest.importorskip("sklearn.base")
    stac = dc.Stac(method="nominal")
    assert stac.get_params() == {"method": "nominal", "options": None}
    copy = sklearn.clone(stac)
    assert copy is not stac and copy.get_params() == stac.get_params()
    assert dc.Pneumatic(jobs=2).set_params(jobs=1).jobs == 1
    assert "_batch" not in dc.Pneumatic().get_params()
    with pytest.raises(OptionError, match="has no parameter 'job'"):
        dc.SGP().set_params(job=2)


@pytest.mark.parametrize("estimator, call", [
    (dc.Stac, lambda e: e.save("x.calib.yaml")),
    (dc.SGP, lambda e: e.predict(SAMPLE / "arm3_dynamics.h5")),
    (dc.Pneumatic, lambda e: e.save("x.pneumatic.yaml")),
])  # fmt: skip
def test_an_unfitted_estimator_says_so(estimator, call):
    with pytest.raises(NotFittedError, match="is not fitted yet: call fit"):
        call(estimator())


def test_a_failed_refit_leaves_the_last_fit_whole(tmp_path):
    # a trial: log_path_ named the failed log while the calibration was the first one's
    stac = dc.Stac(method="nominal").fit(SAMPLE / "finger_hidden_nonlinearity.h5")
    with pytest.raises(DiegocalError):
        stac.fit(SAMPLE / "arm3_dynamics.h5")
    assert stac.log_path_ == SAMPLE / "finger_hidden_nonlinearity.h5"
    from diegocal.io import load_yaml

    stac.save(tmp_path / "c.calib.yaml")
    assert load_yaml(tmp_path / "c.calib.yaml")["log"].endswith("finger_hidden_nonlinearity.h5")


@pytest.mark.parametrize("option, value", [
    ("n_blocks", 2), ("alpha", -1.0), ("alpha", 2.0), ("min_gain", -5.0), ("max_rounds", 0), ("jobs", 0),
])  # fmt: skip
def test_diagnose_options_out_of_range_are_one_error(option, value):
    # a trial: n_blocks=2 wrote a diagnosis with no held-out block, read as a clean bill
    with pytest.raises(OptionError, match=f"diagnose option {option} = "):
        replace(DiagnoseOptions(), **{option: value})


def test_diagnose_refuses_too_few_samples():
    short = dc.load_log(SAMPLE / "arm3_hidden_friction.h5").slice(0, 20)
    with pytest.raises(FitError, match="too few samples to diagnose: 20 for 10 blocks"):
        dc.diagnose(short, domain="dynamics")


@pytest.mark.parametrize("kw, error", [
    ({"kind": "foo"}, OptionError), ({"friction": ("x",)}, OptionError), ({"inertia": "x"}, OptionError),
    ({"n_inducing": 0}, OptionError), ({"restarts": -1}, OptionError), ({"jobs": 0}, OptionError),
    ({"hyper_max": 0}, OptionError),
])  # fmt: skip
def test_sgp_options_out_of_range_are_one_error(kw, error):
    with pytest.raises(error):
        SGPOptions(**kw)


def test_a_misspelt_gp_joint_is_an_unknown_name():
    # a trial: gp_joints=("joint_3_typo",) fitted plain PR without a word
    with pytest.raises(UnknownNameError, match="gp_joints \\['joint_3_typo'\\] are not fitted joints"):
        dc.SGP(SGPOptions(kind="sgp", gp_joints=("joint_3_typo",))).fit(SAMPLE / "arm3_dynamics.h5")


def test_a_log_given_as_a_model_is_one_input_error():
    with pytest.raises(InputFileError, match="not a YAML file"):
        dc.predict(SAMPLE / "arm3_dynamics.h5", SAMPLE / "arm3_hidden_friction.h5")
