"""Subnormal floats flushed to zero while the SGP learns, fits and predicts (x86-64 Linux; elsewhere a no-op).

Why: a squared-exponential kernel with short length-scales has entries exp(-d²/2ℓ²) below the
smallest normal double (2.2e-308), and its Cholesky factor and inverse fill in with more.
Arithmetic on such *subnormal* numbers takes a slow microcode path on x86 CPUs: at ℓ ≈ 0.07
input stds (where ML-II's short-length-scale start goes on PR's residual), a 1,000-sample
likelihood took 0.4-0.5 s against 0.05 s, and potrf and potri ran 8-10× slower. With the CPU's
flush-to-zero (FTZ) and denormals-are-zero (DAZ) modes they are 0 instead, which changes the
likelihood by less than 1e-300 of it: on the scale bench's arm the fit is the same to every printed
digit and takes 33 CPU-s against 39 at 5,000 samples, 47 against 59 at 20,000.

The modes are bits of the SSE control register (MXCSR), per thread, inherited by the threads a
thread starts (the ``jobs`` workers of :func:`diegocal.parallel.thread_map`). They are set and
restored through glibc's ``fegetenv``/``fesetenv``, whose x86-64 ``fenv_t`` holds MXCSR at
byte 28; the first use checks that the bits act (a tiny product is 0) and otherwise turns this
off for the process. numpy's ``finfo`` is computed here first: numpy 1.26 (the oldest we allow)
computes it on first use and, under FTZ, warns that the smallest subnormal is zero (numpy 2 takes
it from C).
"""

from __future__ import annotations

import contextlib
import ctypes
import platform
import sys

import numpy as np

MXCSR_OFFSET = 28  # glibc x86-64 fenv_t: the SSE control and status register's place
FTZ_DAZ = 0x8040  # MXCSR bits 15 (flush to zero) and 6 (denormals are zero)
MXCSR_MASKS = 0x1F80  # the six exception masks, all set by default
FENV_BYTES = 64  # fenv_t is 32 bytes; the buffer leaves room

np.finfo(np.float64), np.finfo(np.float32)  # before any FTZ: finfo caches its smallest subnormal


def _libm():
    """glibc's libm on x86-64 Linux, else None (then :func:`flushed` does nothing)."""
    if sys.platform != "linux" or platform.machine() != "x86_64" or ctypes.sizeof(ctypes.c_void_p) != 8:
        return None
    try:
        return ctypes.CDLL("libm.so.6")  # glibc's stable soname (musl has none: then no flush)
    except OSError:
        return None


_LIBM = _libm()
_WORKS: bool | None = None  # checked on first use


def _mxcsr(env) -> int:
    return int.from_bytes(env.raw[MXCSR_OFFSET : MXCSR_OFFSET + 4], "little")


def _flush():
    """Set MXCSR's FTZ and DAZ bits; returns the saved environment, or None where the
    environment cannot be read or does not look like x86-64 glibc's."""
    env = ctypes.create_string_buffer(FENV_BYTES)
    if _LIBM.fegetenv(env) != 0 or _mxcsr(env) & MXCSR_MASKS != MXCSR_MASKS:
        return None
    saved = ctypes.create_string_buffer(env.raw, FENV_BYTES)
    mxcsr = _mxcsr(env) | FTZ_DAZ
    env[MXCSR_OFFSET : MXCSR_OFFSET + 4] = mxcsr.to_bytes(4, "little")
    return saved if _LIBM.fesetenv(env) == 0 else None


def _tiny_product_is_zero() -> bool:
    with np.errstate(under="ignore"):  # whatever the caller's np.seterr
        return float(np.float64(1e-300) * np.float64(1e-10)) == 0.0


def _works() -> bool:
    """Whether setting the bits flushes a subnormal product to zero (and restoring undoes it)."""
    saved = _flush()
    if saved is None:
        return False
    try:
        zero = _tiny_product_is_zero()
    finally:
        _LIBM.fesetenv(saved)
    return zero and not _tiny_product_is_zero()


@contextlib.contextmanager
def flushed():
    """Context manager (or, called, a decorator: ``@flushed()``): subnormal results and inputs
    read as 0 in this thread (and the threads it starts) inside it; the previous mode comes back
    on exit. Nested uses are fine."""
    global _WORKS
    if _LIBM is not None and _WORKS is None:
        _WORKS = _works()
    saved = _flush() if _LIBM is not None and _WORKS else None
    try:
        yield
    finally:
        if saved is not None:
            _LIBM.fesetenv(saved)


def active() -> bool:
    """Whether subnormals are flushed in this thread now (a tiny product is 0)."""
    return _tiny_product_is_zero()
