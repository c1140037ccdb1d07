"""glibc's allocator told to keep freed memory for reuse (issue #33: long logs).

The kinematics diagnosis's sweeps and STAC's steps make and drop temporaries of one to a hundred
megabytes many thousand times. By default glibc maps each such block afresh from the system and
unmaps it when freed (above its mmap threshold, 128 KB to 32 MB as it adapts), so every use faults
in zeroed pages: system time, and user time spent touching them. With the threshold raised to
MMAP_THRESHOLD the blocks come from the heap and are reused; the heap gives memory back once TRIM_THRESHOLD
lies free at its top. Measured on the 60-s diego kinematics diagnosis (``--jobs 2``, two runs
each): 68.9 s wall and 11.5 s system time → 64.9 s and 8.1 s, the same peak memory. Arrays larger
than MMAP_THRESHOLD (STAC's States on a 10-minute log) are still mapped and given back when freed.

Only the command line (and batch's workers) call :func:`reuse_freed_memory`: a process-wide
setting is the program's to choose, not a library's. A user's own ``MALLOC_MMAP_THRESHOLD_`` wins.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import sys

#: Blocks at least this large are still mapped from the system and given back when freed.
MMAP_THRESHOLD = 256 << 20
#: Free memory at the heap's top beyond this is given back to the system.
TRIM_THRESHOLD = 1 << 30
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3  # mallopt's parameters (malloc.h)


def reuse_freed_memory() -> bool:
    """Raise glibc's mmap and trim thresholds (module docstring); whether it was done (not on
    another C library or system, nor where the user set ``MALLOC_MMAP_THRESHOLD_``)."""
    if not sys.platform.startswith("linux") or "MALLOC_MMAP_THRESHOLD_" in os.environ:
        return False
    try:
        mallopt = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").mallopt
    except (OSError, AttributeError):  # no glibc (musl has no mallopt)
        return False
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    return bool(mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)) and bool(mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD))
