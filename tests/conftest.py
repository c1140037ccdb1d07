"""Shared test set-up: BLAS on one thread for the whole suite (two cores shared by many processes:
one thread is far faster than contention; threadpoolctl is a dependency of diegocal).

ezc3d is imported first: it and pymupdf (the report tests' PDF reader, a dev extra) each carry a
SWIG runtime, and whichever registers ``std::vector<std::string>`` first wins; with pymupdf first,
ezc3d can no longer write a C3D's string parameters ("POINT:UNITS could not be converted to
string"). diegocal itself never loads both in one process."""

import ezc3d  # noqa: F401  (before pymupdf, see above)
import pytest
from threadpoolctl import threadpool_limits


@pytest.fixture(autouse=True, scope="session")
def _one_blas_thread():
    with threadpool_limits(limits=1):
        yield
