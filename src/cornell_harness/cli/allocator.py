"""The C allocator's thresholds for numpy's large temporaries (glibc only; elsewhere nothing is changed).

glibc's malloc serves a block above its mmap threshold (128 KiB, raised
dynamically up to the largest block freed) with a fresh ``mmap`` and
returns it to the kernel when it is freed; it also gives back the free top
of its heap above the trim threshold. numpy's temporaries of a 256² image
are 0.5-1.5 MB each, so scoring one allocates and frees dozens of them, and
every one comes back from the kernel as fresh pages that it must zero and
map again. In ``cbox compare-image``'s warm call that was 12-15 ms of 30
(BENCHMARKS.md, compare-image), and whether a process paid it depended on what it
had freed before. Our renderers' wavefront buffers (a few MB per work unit)
paid the same: 7-10% of the path tracer's time per path (BENCHMARKS.md). Every
``cbox`` command sets the thresholds at its start (:func:`cornell_harness.cli.app.main`):
the program's choice, never a library's, which a user may import into a
process of their own. Raising both thresholds (``mallopt``, as the environment
variables ``MALLOC_MMAP_THRESHOLD_`` and ``MALLOC_TRIM_THRESHOLD_`` do) keeps
freed blocks in the heap for the next temporary: the process keeps up to
:data:`TRIM_THRESHOLD` of freed memory instead of returning it.
"""

from __future__ import annotations

import ctypes
import functools

#: Blocks below this come from the heap and are reused after being freed (glibc's largest dynamic threshold).
MMAP_THRESHOLD = 32 * 2**20
#: Free memory at the top of the heap kept for reuse, up to this.
TRIM_THRESHOLD = 64 * 2**20
# mallopt's parameter numbers (glibc's malloc.h).
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3


@functools.cache
def keep_freed_memory() -> bool:
    """Raise glibc's mmap and trim thresholds for this process (once); False where there is no glibc."""
    try:
        # The C library this process already runs on: find_library("c") would run ldconfig (~4 ms), which
        # every cbox command now pays since cornell_harness.cli.app calls this at its start.
        libc = ctypes.CDLL(None)
        mallopt = libc.mallopt
        libc.gnu_get_libc_version  # glibc's own symbol: another libc's mallopt may read these numbers otherwise
    except (OSError, AttributeError):
        return False
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    return bool(mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)) & bool(mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD))
