"""A pot whose line drops to 0 V for a sample or three (issue #31): the tracking spreads its
spikes over the markers' residuals, which the marker-outlier test read as the markers' own. The
flags a pot carried are dropped (:mod:`diegocal.diagnose.kinematics_outliers`); a marker's own
outliers are still named."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from diegocal.diagnose.kinematics import KinematicsAdapter
from diegocal.evaluate import split_blocks
from diegocal.io import make_stream
from experiments.kinematics_oov import clean_session

#: The frames a pot drops out at, and for how many samples.
DROPS = {120: 2, 455: 1, 800: 3, 1130: 1, 1470: 2}


def dropped(seed: int, pot: str, duration: float = 20.0):
    """A clean finger session cut to ``duration`` s with ``pot`` reading 0 V on DROPS: (log, robot)."""
    log, robot, _, _ = clean_session(seed)
    log = log.take(np.flatnonzero(log.time < log.time[0] + duration))
    names = log.streams["pots"].names
    p = log.streams["pots"].data.copy()
    for k, n in DROPS.items():
        p[k : k + n, names.index(pot)] = 0.0
    return replace(log, streams={**log.streams, "pots": make_stream(names, p)}), robot


def _faults(log, robot, progress=None):
    adapter = KinematicsAdapter(log, robot)
    adapter.progress = progress
    fitted = adapter.fit((), split_blocks(log.n_samples, 10).mask("train"))
    return adapter, adapter.faults(fitted, adapter.residuals(fitted))


@pytest.fixture(scope="module")
def fdp_drops():
    return dropped(4, "fdp")


def test_a_pots_dropouts_are_no_marker_outliers(fdp_drops):
    log, robot = fdp_drops
    said = []
    _, faults = _faults(log, robot, said.append)
    assert [f.term.cause for f in faults if f.term.cause == "marker_outliers"] == []
    assert any(s.startswith("fdp:") for s in said)  # the pot is said


def test_a_markers_own_outliers_are_still_named_beside_a_pots_dropouts(fdp_drops):
    log, robot = fdp_drops
    names = log.streams["markers"].names
    x = log.streams["markers"].data.copy()
    ghosts = [300, 301, 302, 1000]
    x[ghosts, 1] += np.array([0.03, -0.02, 0.01])  # 4 cm: a reflection
    log = replace(log, streams={**log.streams, "markers": make_stream(names, x)})
    _, faults = _faults(log, robot)
    out = [f for f in faults if f.term.cause == "marker_outliers"]
    assert len(out) == 1
    assert out[0].term.extra["frames"] == {names[1]: ghosts}
