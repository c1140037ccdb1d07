"""The command line keeps freed memory for reuse (diegocal/allocator.py): done on glibc, skipped
where the user chose the threshold."""

import sys

import pytest

from diegocal.allocator import reuse_freed_memory


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt")
def test_the_thresholds_are_set_on_glibc_and_left_to_the_user_when_chosen(monkeypatch):
    import platform

    if platform.libc_ver()[0] != "glibc":
        pytest.skip("not glibc")
    assert reuse_freed_memory() is True
    monkeypatch.setenv("MALLOC_MMAP_THRESHOLD_", "131072")
    assert reuse_freed_memory() is False
