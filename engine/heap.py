"""Give freed memory back to the system during a long build (glibc's allocator on Linux; elsewhere nothing).

A build frees as much as it allocates: each chunk, block and batch is let go once handled. glibc's allocator
keeps what is freed for reuse, and its threshold for serving big buffers by mmap rises after each big free,
so big pickles (a block's task, a chunk's results) end up in the heap and fragment it: the 16x terrain's
build process grew by 100+ MB of freed memory in the crossing repair. Fixing the mmap threshold keeps big
buffers out of the heap (each returned whole when freed), and trimming after each phase returns what is free.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import sys
from functools import cache

#: glibc's mallopt parameters (malloc.h).
_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3

#: Buffers this large or larger get their own mapping, returned to the system when freed.
MMAP_THRESHOLD_BYTES = 256 << 10
#: Free memory at the top of the heap beyond this is returned to the system at once.
TRIM_THRESHOLD_BYTES = 4 << 20


@cache
def _libc() -> ctypes.CDLL | None:
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
    except OSError:
        return None
    # musl and other C libraries have no mallopt / malloc_trim: nothing to tune there.
    return libc if hasattr(libc, "mallopt") and hasattr(libc, "malloc_trim") else None


@cache
def keep_big_buffers_out_of_the_heap() -> bool:
    """Fix glibc's mmap and trim thresholds for this process (see the module's docstring), once; False where
    there is no glibc."""
    libc = _libc()
    if libc is None:
        return False
    return bool(libc.mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES)) and bool(
        libc.mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES)
    )


def release_free_memory() -> None:
    """Return the allocator's free memory to the system (glibc's ``malloc_trim``); after a phase of a build."""
    libc = _libc()
    if libc is not None:
        libc.malloc_trim(0)
