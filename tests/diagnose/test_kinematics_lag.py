"""A pot read through a filter (an RC on its line) lags by an error in proportion to its speed: no
cause of the vocabulary, and not a dead band, whose column (the direction of motion) takes up part
of it. The pot is ``unexplained``, its lag among the flexible models a pot term is measured
against (:mod:`diegocal.diagnose.kinematics_curves`)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from diegocal.diagnose import DiagnoseOptions, diagnose
from diegocal.diagnose.kinematics_curves import reading_rate
from diegocal.io import make_stream
from experiments.kinematics_oov import clean_session


def low_passed(seed: int, pot: str, tau: float):
    """A clean finger session (experiments/kinematics_oov.py) with ``pot``'s reading through a
    first-order filter of time constant ``tau`` (s): (log, robot)."""
    log, robot, _, _ = clean_session(seed)
    names = log.streams["pots"].names
    p = log.streams["pots"].data.copy()
    i = names.index(pot)
    a = np.exp(-np.diff(log.time).mean() / tau)
    for k in range(1, p.shape[0]):
        p[k, i] = a * p[k - 1, i] + (1 - a) * p[k, i]
    return replace(log, streams={**log.streams, "pots": make_stream(names, p)}), robot


def test_a_readings_rate_is_its_slope():
    """The rate a lag's column is made of: a ramp's slope, and a sine's derivative within the
    smoother's error (11 samples of a 2-s period at 100 Hz)."""
    t = np.arange(500) / 100.0
    assert np.allclose(reading_rate(t, 3.0 * t - 1.0), 3.0)
    w = 2 * np.pi / 2.0
    assert np.allclose(reading_rate(t, np.sin(w * t))[10:-10], w * np.cos(w * t)[10:-10], atol=0.01 * w)


def test_a_pot_behind_a_filter_is_unexplained_not_a_backlash():
    """fdp behind a 30-ms RC: its dead band removed part of the validation error and was named
    ``backlash``; its lag removes more, so fdp is ``unexplained`` with the dead band as stand-in."""
    log, robot = low_passed(5, "fdp", 0.03)
    d = diagnose(log, robot, DiagnoseOptions(domain="kinematics"))
    assert [(f.cause, f.channel) for f in d.findings] == [("unexplained", "fdp")]
    assert d.findings[0].evidence["stand_in"]["term"] == "backlash:fdp"


def test_a_lagging_pot_is_no_member_of_a_common_backlash():
    """mcp_abd behind a 30-ms RC (seed 3): the dead bands of six pots tested as one common backlash,
    whose mcp_abd member was added without the neighbours' test a single pot term runs; its lag
    removes more, so mcp_abd is ``unexplained`` with the dead band as stand-in."""
    log, robot = low_passed(3, "mcp_abd", 0.03)
    d = diagnose(log, robot, DiagnoseOptions(domain="kinematics"))
    assert [(f.cause, f.channel) for f in d.findings] == [("unexplained", "mcp_abd")]
    assert d.findings[0].evidence["stand_in"]["term"] == "backlash:mcp_abd"
