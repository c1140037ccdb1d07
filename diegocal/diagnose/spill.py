"""A round's candidate columns on disk (issue #33: long logs).

The kinematics diagnosis makes every candidate's columns in one sweep over the log and the engine
then reads each candidate's a piece of samples at a time (a fit, a test, a channel's gain). Held
in memory, a round's columns grow with the log (about 2.7 MB per second of a diego log: 1.6 GB
for ten minutes). :class:`Spill` writes them, as made, into one temporary file (unlinked: the
operating system removes it when the round's candidates are dropped or the process ends) and a
:class:`DiskArray` reads back only the samples asked for, so the process holds a block and a
piece, whatever the log's length. The values are the same bits as the in-memory arrays'. The
file goes where :mod:`tempfile` puts it (``TMPDIR``); the kernel's page cache may keep it in
memory it can take back.
"""

from __future__ import annotations

import os
import shutil
import tempfile
import threading

import numpy as np

from diegocal.errors import ScratchSpaceError

#: Said with a failed write: what the file needs.
ROOM = "about 8 MB per second of a 38-joint log: the columns and each block's linearisation"


class Spill:
    """One temporary file that column arrays are laid out in, end to end."""

    def __init__(self):
        try:
            self._file = tempfile.TemporaryFile(prefix="diegocal-columns-")
        except OSError as exc:
            raise _no_room(exc) from None
        self.fd = self._file.fileno()
        self._end = 0

    def close(self) -> None:
        """Give the file's space back (its arrays can no longer be read)."""
        self._file.close()

    def array(self, shape: tuple, dtype) -> DiskArray:
        """A new (uninitialised) array of ``shape`` in the file: rows written by :meth:`DiskArray.write`."""
        out = DiskArray(self, self._end, tuple(int(n) for n in shape), np.dtype(dtype))
        self._end += out.nbytes
        return out

    def zeros(self, shape: tuple, dtype=float) -> DiskArray:
        """A new array of ``shape`` in the file, zero until rows are written (the file is extended
        over it: a hole, which reads as zeros and takes no room until written)."""
        out = self.array(shape, dtype)
        try:
            os.ftruncate(self.fd, max(self._end, os.fstat(self.fd).st_size))
        except OSError as exc:
            raise _no_room(exc) from None
        return out


def on_disk(*arrays: np.ndarray, spill: Spill | None = None) -> tuple:
    """``arrays`` (each (T, ...)) written to ``spill`` (default: a new one), as DiskArrays: a
    whole-log array that is read a block of rows at a time (or read back whole now and then) need
    not be held (issue #33)."""
    spill = Spill() if spill is None else spill
    out = []
    for x in arrays:
        x = np.asarray(x)
        d = spill.array(x.shape, x.dtype)
        d.write(0, x)
        out.append(d)
    return tuple(out)


class DiskArray:
    """An array (T, ...) in a :class:`Spill`'s file, read by rows: ``x[samples]`` (a slice or
    integer indices) reads the span they cover and returns those rows as a numpy array."""

    def __init__(self, spill: Spill, offset: int, shape: tuple, dtype: np.dtype):
        self.spill, self.offset, self.shape, self.dtype = spill, offset, shape, dtype
        self.ndim = len(shape)
        self.row_bytes = int(np.prod(shape[1:], dtype=np.int64)) * dtype.itemsize
        self.nbytes = self.row_bytes * shape[0]

    def write(self, start: int, rows: np.ndarray) -> None:
        """Rows ``start`` to ``start + len(rows)`` set to ``rows`` (B, ...)."""
        data = np.ascontiguousarray(rows, self.dtype)
        if data.shape[1:] != self.shape[1:] or not 0 <= start <= self.shape[0] - data.shape[0]:
            raise ValueError(f"rows of shape {data.shape} at {start} do not fit an array of shape {self.shape}")
        view, at = memoryview(data).cast("B"), self.offset + start * self.row_bytes
        while view.nbytes:
            try:
                n = os.pwrite(self.spill.fd, view, at)
            except OSError as exc:
                raise _no_room(exc) from None
            view, at = view[n:], at + n

    def span(self, first: int, stop: int) -> np.ndarray:
        """Rows ``first`` to ``stop`` (exclusive), read from the file."""
        out = np.empty((max(stop - first, 0), *self.shape[1:]), self.dtype)
        view, at = memoryview(out).cast("B"), self.offset + first * self.row_bytes
        while view.nbytes:
            n = os.preadv(self.spill.fd, [view], at)
            if n <= 0:
                raise OSError(f"the candidate columns' temporary file ended early (at byte {at})")
            view, at = view[n:], at + n
        return out

    def __getitem__(self, key):
        if isinstance(key, slice):
            first, stop, step = key.indices(self.shape[0])
            return self.span(first, stop)[::step] if step > 0 else self.span(0, self.shape[0])[key]
        rows = np.arange(self.shape[0])[key] if np.asarray(key).dtype == bool else np.asarray(key, np.intp)
        rows = np.where(rows < 0, rows + self.shape[0], rows)
        if rows.size == 0:
            return np.empty((0, *self.shape[1:]), self.dtype)
        first = int(rows.min())
        return self.span(first, int(rows.max()) + 1)[rows - first]

    def __len__(self) -> int:
        return self.shape[0]

    def __array__(self, dtype=None, copy=None):
        out = self.span(0, self.shape[0])
        return out if dtype is None else out.astype(dtype, copy=False)

    def __reduce__(self):  # sent to another process as the array it holds (the file stays here)
        return (np.asarray, (np.asarray(self),))


class BlockStore:
    """Named arrays of blocks of frames (T rows each), kept in a :class:`Spill` as made so that a
    later pass reads them back instead of making them again; a block is read only once all of it
    is written (producers in threads write different blocks). A store that cannot write (no room)
    keeps nothing more, and its caller makes the blocks again: it is a saving, never a need."""

    def __init__(self, T: int):
        self.T, self._arrays, self._done, self._lock = T, None, set(), threading.Lock()
        self._spill: Spill | None = None
        self.working = True

    def _start(self, arrays: dict) -> None:
        """Lay out the arrays for T frames, if the disk has room for them twice over (the
        candidate columns, which the diagnosis needs, go to the same folder)."""
        size = sum(self.T * a[0].nbytes for a in arrays.values())
        if shutil.disk_usage(tempfile.gettempdir()).free < 2 * size:
            raise OSError("not room enough for the block store beside the candidate columns")
        self._spill = Spill()
        self._arrays = {k: self._spill.array((self.T, *a.shape[1:]), a.dtype) for k, a in arrays.items()}

    def _stop(self) -> None:
        """Keep nothing more, and give the file's space back."""
        self.working, self._arrays, self._done = False, None, set()
        if self._spill is not None:
            self._spill.close()
            self._spill = None

    def get(self, sl: slice) -> dict | None:
        """The arrays of the block ``sl`` when it was kept, else None."""
        with self._lock:  # (a failed write elsewhere closes the file: not while it is read)
            if sl.start not in self._done:
                return None
            return {k: a.span(sl.start, sl.stop) for k, a in self._arrays.items()}

    def put(self, sl: slice, arrays: dict) -> None:
        """Keep the block ``sl``'s ``arrays`` ({name: (B, ...)})."""
        with self._lock:
            if not self.working:
                return
            try:
                if self._arrays is None:
                    self._start(arrays)
                for k, a in arrays.items():
                    self._arrays[k].write(sl.start, a)
            except (OSError, ScratchSpaceError):
                self._stop()
                return
            self._done.add(sl.start)


def _no_room(exc: OSError) -> ScratchSpaceError:
    """The error a failed temporary file says, with where it was and what to change."""
    where = tempfile.gettempdir()
    return ScratchSpaceError(
        f"cannot write the candidate columns' temporary file in {where}: {exc.strerror or exc}; "
        f"set TMPDIR to a folder with room ({ROOM})"
    )
