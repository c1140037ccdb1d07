"""A kinematic sensor fault no cause of the vocabulary describes is called `unexplained`, never a
wrong name (issue #31, item 1): shapes of experiments/kinematics_oov.py, written apart from the
simulator, added to a clean finger session."""

from __future__ import annotations

import numpy as np

from diegocal.diagnose import DiagnoseOptions, diagnose
from experiments.kinematics_oov import MARKER_NOISE, POT_NOISE, add_shape, clean_session


def test_the_shapes_are_added_to_one_channel_at_their_size():
    clean, *_ = clean_session(5)
    for shape in ("worn_track", "runout", "warm_up", "crosstalk"):
        log, _, channel, ratio = add_shape(shape, 5)
        d = log.streams["pots"].data - clean.streams["pots"].data
        i = log.streams["pots"].names.index(channel)
        assert np.abs(np.delete(d, i, axis=1)).max() == 0.0  # one pot only
        size = np.sqrt(np.mean(d[:, i] ** 2)) if shape == "crosstalk" else np.abs(d[:, i]).max()
        assert abs(size / POT_NOISE - ratio) < 0.05 * ratio, shape
    log, _, marker, ratio = add_shape("wobble", 5)
    m = log.streams["markers"].names.index(marker)
    d = log.streams["markers"].data[:, m] - clean.streams["markers"].data[:, m]
    assert abs(np.sqrt(np.nanmean(d**2)) / MARKER_NOISE - ratio) < 0.05 * ratio  # RMS per axis


def test_a_worn_pot_track_is_unexplained_on_its_pot_not_a_transfer_curve():
    """A dip a twentieth of the pot's range wide: the cubic transfer curve explains little of what
    a flexible function of the reading does, so the pot is ``unexplained`` (no name at all)."""
    log, robot, channel, _ = add_shape("worn_track", 5)
    d = diagnose(log, robot, DiagnoseOptions(domain="kinematics"))
    assert [(f.cause, f.channel) for f in d.findings] == [("unexplained", channel)]
    region = d.findings[0].term.region
    assert region.variable == f"p.{channel}"
