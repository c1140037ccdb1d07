"""What a calibration did with each pot's gain and bias (:meth:`Calibration.pot_roles`), and the unit
of each sensor type's readings: an encoder's gain is 1 by design (not unobservable because it has
no standard error), its bias in rad; a gauge bias is held at nominal; an unobservable pot keeps both;
a method that gives no standard errors at all still estimated what it did not hold."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from diegocal.stac.calibration import POT_UNITS, READING_UNITS, Calibration

NAN = np.nan


def _calibration(**kwargs) -> Calibration:
    """pot1-pot3 rotary, enc4 an encoder; pot1's bias a root gauge, enc4's a leaf gauge, pot3 unobservable."""
    kinds = ("rotary", "rotary", "rotary", "encoder")
    cal = Calibration(
        pot_names=("pot1", "pot2", "pot3", "enc4"),
        gain=np.array([1.01, 0.98, 1.0, 1.0]),
        bias=np.array([2.5, 2.51, 2.5, 0.0]),
        marker_names=("m1",),
        marker_links=("link1",),
        marker_xyz=np.zeros((1, 3)),
        gain_se=np.array([2e-4, 3e-4, NAN, NAN]),
        bias_se=np.array([NAN, 2e-4, NAN, NAN]),
        gauges=(
            {"joint": "j1", "pot": "pot1", "kind": "root", "reason": "..."},
            {"joint": "j4", "pot": "enc4", "kind": "leaf", "reason": "...", "markers": ["m1"]},
        ),
        unobservable=({"pot": "pot3", "joints": ["j3"], "reason": "no marker moves with joint j3"},),
        pot_units=tuple(POT_UNITS[k] for k in kinds),
    )
    return replace(cal, **kwargs)


def test_each_gain_and_bias_has_its_role():
    assert _calibration().pot_roles() == {
        "pot1": ("estimated", "gauge"),
        "pot2": ("estimated", "estimated"),
        "pot3": ("unobservable", "unobservable"),
        "enc4": ("design", "gauge"),  # the trial's enc6: not 'nominal: unobservable'
    }


def test_roles_survive_calib_yaml_and_files_without_units_ask_the_kinds():
    cal = _calibration()
    assert Calibration.from_dict(cal.to_dict()).pot_roles() == cal.pot_roles()
    bare = replace(cal, pot_units=())  # layout 1 wrote no units: the robot's kinds tell the encoder
    assert bare.pot_roles()["enc4"] == ("nominal", "gauge")
    assert bare.pot_roles({"enc4": "encoder"})["enc4"] == ("design", "gauge")


def test_a_method_without_standard_errors_still_estimated_what_it_did_not_hold():
    ekf = _calibration(method="ekf", gain_se=np.full(4, NAN), bias_se=np.full(4, NAN), gauges=(), unobservable=())
    assert ekf.pot_roles() == {n: ("estimated", "estimated") for n in ("pot1", "pot2", "pot3")} | {
        "enc4": ("design", "estimated")
    }
    nominal = replace(ekf, method="nominal")
    assert set(nominal.pot_roles().values()) == {("nominal", "nominal"), ("design", "nominal")}


def test_each_sensor_type_reads_in_its_own_unit():
    assert READING_UNITS == {"rotary": "V", "linear": "V", "tendon": "V", "encoder": "rad", "markers": "m"}
    baseline = _calibration().to_dict()["baseline"]
    written = {t["channel"]: t["parameters"] for t in baseline if t["cause"] == "pot_transfer"}
    assert (written["enc4"]["gain"]["unit"], written["enc4"]["bias"]["unit"]) == ("1", "rad")
