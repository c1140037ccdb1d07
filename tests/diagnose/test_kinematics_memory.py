"""What keeps a long log's kinematics diagnosis within memory (issue #33): the round's candidate
columns on disk (diegocal/diagnose/spill.py) and the outlier test's running median a chunk of
frames at a time; each the same numbers as the whole arrays in memory."""

from __future__ import annotations

import errno
import os
import pickle
import shutil
import warnings
from types import SimpleNamespace

import numpy as np
import pytest

from diegocal.diagnose.kinematics_lin import running_median
from diegocal.diagnose.spill import BlockStore, Spill, on_disk
from diegocal.errors import ScratchSpaceError


def test_columns_read_back_from_disk_are_the_rows_written():
    rng = np.random.default_rng(0)
    spill = Spill()
    pot = rng.normal(size=(1000, 2)).astype(np.float32)
    marker = rng.normal(size=(1000, 3, 4)).astype(np.float32)
    a, b = spill.array(pot.shape, np.float32), spill.array(marker.shape, np.float32)
    for start in range(0, 1000, 250):  # a block at a time, as the sweep writes them
        b.write(start, marker[start : start + 250])
        a.write(start, pot[start : start + 250])
    train = np.flatnonzero(rng.random(1000) < 0.6)
    assert np.array_equal(a[train], pot[train]) and np.array_equal(b[train], marker[train])
    assert np.array_equal(b[100:400], marker[100:400]) and np.array_equal(b[::7], marker[::7])
    assert np.array_equal(np.asarray(b), marker) and b.shape == marker.shape and b.ndim == 3
    assert np.array_equal(b[train[::-1]], marker[train[::-1]])  # any order
    assert np.array_equal(pickle.loads(pickle.dumps(b)), marker)  # another process gets the array
    with pytest.raises(ValueError, match="do not fit"):
        a.write(900, pot[:200])


def test_whole_log_arrays_on_disk_read_back_bit_for_bit_and_unwritten_rows_as_zeros():
    """:func:`on_disk` (the pot candidates' ∂p̂/∂θ, a fit's deleted residuals) and
    :meth:`Spill.zeros` (the slip scan's sums, written a block of rows at a time)."""
    rng = np.random.default_rng(3)
    f, r = rng.normal(size=(1000, 2)), rng.normal(size=(1000, 4, 3))
    spill = Spill()
    df, dr = on_disk(f, r, spill=spill)
    assert np.array_equal(df[250:500], f[250:500]) and np.array_equal(np.asarray(dr), r)
    z = spill.zeros((600, 3, 3))
    z.write(100, r[:50, :3])  # a block's rows; the rest never written
    got = np.asarray(z)
    assert np.array_equal(got[100:150], r[:50, :3]) and not got[:100].any() and not got[150:].any()
    (alone,) = on_disk(f)  # a file of its own
    assert np.array_equal(alone[::3], f[::3]) and alone.spill is not spill


def test_the_running_median_a_chunk_at_a_time_is_each_frame_s_median():
    rng = np.random.default_rng(1)
    x = rng.normal(size=(2500, 3, 3))
    x[rng.random(x.shape) < 0.2] = np.nan
    x[1020:1030, 1] = np.nan  # a gap across a chunk's edge
    half = 8
    got = running_median(x, half, chunk=1024)
    for t in (0, 5, 1016, 1023, 1024, 1030, 2048, 2499):  # every chunk's edges and the log's
        window = x[max(t - half, 0) : t + half + 1]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # an all-NaN window's median is NaN
            want = np.nanmedian(window, axis=0)
        assert np.array_equal(got[t], want, equal_nan=True)



def test_a_full_disk_is_one_error_that_says_where_and_what_to_change(monkeypatch):
    def full(*args):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    a = Spill().array((10, 2), np.float32)
    monkeypatch.setattr(os, "pwrite", full)
    with pytest.raises(ScratchSpaceError, match="No space left on device; set TMPDIR to a folder with room"):
        a.write(0, np.zeros((10, 2)))


def test_a_block_store_gives_back_the_blocks_kept_and_nothing_once_the_disk_is_full(monkeypatch):
    """The sweep's linearisations kept between passes (:class:`BlockStore`): a kept block reads
    back bit for bit, one never kept reads None (the caller makes it), and a full disk, or one
    without room for the store beside the candidate columns, turns the store off (its file given
    back) instead of failing the diagnosis."""
    rng = np.random.default_rng(2)
    J, w = rng.normal(size=(1000, 5, 3)), rng.normal(size=(1000, 5))
    store = BlockStore(1000)
    for start in (0, 500):
        sl = slice(start, start + 250)
        store.put(sl, {"J": J[sl], "w": w[sl]})
    got = store.get(slice(500, 750))
    assert np.array_equal(got["J"], J[500:750]) and np.array_equal(got["w"], w[500:750])
    assert store.get(slice(250, 500)) is None
    monkeypatch.setattr(os, "pwrite", lambda *a: (_ for _ in ()).throw(OSError(errno.ENOSPC, "full")))
    store.put(slice(250, 500), {"J": J[250:500], "w": w[250:500]})
    assert not store.working and store.get(slice(250, 500)) is None
    assert store.get(slice(0, 250)) is None  # the file given back: the caller makes the blocks again
    monkeypatch.undo()
    small = BlockStore(1000)  # a disk without room for the store twice over: nothing kept, no error
    monkeypatch.setattr(shutil, "disk_usage", lambda path: SimpleNamespace(free=J.nbytes + w.nbytes))
    small.put(slice(0, 250), {"J": J[:250], "w": w[:250]})
    assert not small.working and small.get(slice(0, 250)) is None
