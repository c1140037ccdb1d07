"""Least squares on a tall system, a chunk of rows at a time (issue #33: long logs).

The triangular factor R of the QR factorisation of the augmented matrix ``[X y]`` is updated
chunk by chunk (TSQR: the QR of the last R stacked on the next rows; Golub & Van Loan, Matrix
Computations, §5.2-5.3), so X is never held whole nor copied. Each update is LAPACK's
triangular-pentagonal QR (``dtpqrt``), which never forms the stacked matrix, a few thousand rows at a
time: Householder QR of a tall block is bound by memory, and on a block in cache it runs about
four times faster than ``numpy.linalg.qr`` of the whole chunk. Everything the fits need follows
from R, because ``[X y] = Q R`` with Q's columns orthonormal:

.. math:: \\|X w - y\\|^2 = \\|R [w; -1]\\|^2, \\qquad X^T X = R_{11}^T R_{11}

so the solution is the minimum-norm one of ``R11 w = r`` (the same as ``numpy.linalg.lstsq`` on
X, to rounding, with its rank cutoff: singular values below ``eps · max(rows, columns)`` times the
largest), the residual sum of squares is exact for that w, and the Gram matrix needs no pass over X.
``lstsq`` instead factors a copy of the whole X (by SVD), and a caller usually made one copy more
to weigh and filter the rows; here each chunk is weighed and filtered as it is added.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import lapack

#: Rows per update: small enough to stay in cache, large enough that numpy's per-call overhead
#: does not count.
CHUNK_ROWS = 2048
#: Rows of one triangular-pentagonal update (:meth:`TallLstsq.add`).
UPDATE_ROWS = 1024


class TallLstsq:
    """Least squares ``min ‖X w − y‖`` over rows given in chunks (:meth:`add`); ``p`` columns."""

    def __init__(self, p: int):
        self.p = int(p)
        self.R = np.zeros((self.p + 1, self.p + 1), order="F")  # upper triangular; zero rows count nothing
        self.rows = 0

    def add(self, X: np.ndarray, y: np.ndarray) -> None:
        """Rows X (m, p) and y (m,) of the system (any m, 0 included)."""
        n = self.p + 1
        for i in range(0, len(y), UPDATE_ROWS):
            block = np.empty((min(UPDATE_ROWS, len(y) - i), n), order="F")
            block[:, :-1] = X[i : i + UPDATE_ROWS]
            block[:, -1] = y[i : i + UPDATE_ROWS]
            # R's strictly lower part is never referenced, so it stays zero
            self.R, _, _, info = lapack.dtpqrt(0, min(32, n), self.R, block, overwrite_a=True, overwrite_b=True)
            assert info == 0, f"dtpqrt: argument {-info} is illegal"
        self.rows += len(y)

    def solve(self) -> tuple[np.ndarray, float]:
        """(w (p,), the residual sum of squares at w)."""
        p = self.p
        R = np.zeros((p + 1, p + 1))
        R[: len(self.R)] = self.R  # fewer rows than columns so far: the rest is zero
        rcond = np.finfo(float).eps * max(self.rows, p)  # numpy.linalg.lstsq's default on X
        w = np.linalg.lstsq(R[:p, :p], R[:p, p], rcond=rcond)[0]
        r = R @ np.append(w, -1.0)
        return w, float(r @ r)

    def gram(self) -> np.ndarray:
        """XᵀX (p, p) = R11ᵀ R11."""
        R11 = self.R[: self.p, : self.p]
        return R11.T @ R11
