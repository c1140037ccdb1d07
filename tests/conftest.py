"""Shared test set-up: BLAS on one thread for the whole suite (two cores shared by many processes:
one thread is far faster than contention; threadpoolctl is a dependency of diegocal)."""

import pytest
from threadpoolctl import threadpool_limits


@pytest.fixture(autouse=True, scope="session")
def _one_blas_thread():
    with threadpool_limits(limits=1):
        yield
