"""cornell_harness.cli.allocator: glibc's thresholds raised once per process, where there is glibc."""

from __future__ import annotations

import platform

from cornell_harness.cli.allocator import keep_freed_memory


def test_the_thresholds_are_set_where_there_is_glibc():
    assert keep_freed_memory() is (platform.libc_ver()[0] == "glibc")
    assert keep_freed_memory() is keep_freed_memory()  # once per process: the cached answer
