"""A marker slip's change-time scan from the training frames' sums alone (issue #33: the other
frames' are zero) picks the same samples as from every frame's."""

import numpy as np

from diegocal.diagnose.kinematics_slip import change_times


def test_scan_of_the_training_frames_equals_that_of_every_frame():
    rng = np.random.default_rng(3)
    T = 1000
    train = np.zeros(T, bool)
    for a, e in ((0, 100), (180, 420), (500, 501), (600, 603), (700, 990)):
        train[a:e] = True
    C = rng.normal(size=(T, 6, 3))
    r = rng.normal(size=(T, 6)) + np.where(np.arange(T) > 300, 0.5, 0.0)[:, None] * C[..., 0]
    w = np.where(train[:, None], rng.uniform(0.5, 2.0, (T, 6)), 0.0)
    Cw = C * w[..., None]
    G, b = np.einsum("trk,trl->tkl", Cw, C), np.einsum("trk,tr->tk", Cw, r)
    every = change_times(train, G, b)
    assert every and every == change_times(train, G[train], b[train])
    assert change_times(np.zeros(T, bool), G[:0], b[:0]) == []
