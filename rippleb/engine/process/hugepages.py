"""Make the fork server cheaper to fork: its private memory mapped by 2 MiB pages.

Why: every row costs two forks of the fork server's memory (its keeper, then its worker)
and two exits. The kernel copies, then tears down, one page-table entry per 4 KiB page the
server has touched: about 120 MB of numpy, scipy, numba and the built-in methods, some
30 000 entries a fork. On the 50-device publication that was most of the kernel's 43 % of
the run's CPU (``perf``: ``copy_page_range`` in ``dup_mmap``, ``unmap_page_range`` in
``exit_mmap``; docs/robustness.md, "The fork itself"). A range the kernel maps by one 2 MiB page is one entry
to copy and to tear down instead of 512.

:func:`collapse_private_memory` asks the kernel, once, after the server has loaded what
every job needs, to re-map its anonymous private memory by 2 MiB pages
(``madvise(MADV_COLLAPSE)``, Linux 6.1). The bytes do not change, nor what any process can
read or write: a job that writes to such a page gets its own 4 KiB copy, as before (the
kernel splits the shared mapping first). The flags the regions had stay as they are, so
memory a job allocates later is mapped as the host's settings say, as before. Where the
kernel does not offer it (older kernels, other systems) nothing happens.
"""

from __future__ import annotations

import ctypes
import sys

MADV_COLLAPSE = 25
HUGE_PAGE = 2 << 20


def collapse_private_memory() -> int:
    """Collapse this process's anonymous private writable memory into 2 MiB pages where
    the kernel can; returns how many it mapped so (0 where it offers none)."""
    if not sys.platform.startswith("linux"):
        return 0
    madvise = ctypes.CDLL(None, use_errno=True).madvise
    madvise.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int]
    collapsed = 0
    for start, end in _aligned_private_ranges():
        if madvise(start, end - start, MADV_COLLAPSE) == 0:
            collapsed += (end - start) // HUGE_PAGE
    return collapsed


def _aligned_private_ranges() -> list[tuple[int, int]]:
    """The whole 2 MiB pages inside each anonymous private writable mapping (the heap and
    anonymous ``mmap``s: what the interpreter and the libraries allocated), from
    ``/proc/self/maps``. Files' mappings are left alone: their pages are shared with the
    page cache and their entries are not copied at a fork."""
    ranges = []
    try:
        with open("/proc/self/maps") as maps:
            lines = maps.readlines()
    except OSError:
        return ranges
    for line in lines:
        fields = line.split()
        perms, path = fields[1], fields[5] if len(fields) > 5 else ""
        if not perms.startswith("rw") or perms[3] != "p" or path not in ("", "[heap]"):
            continue
        low, high = (int(x, 16) for x in fields[0].split("-"))
        start, end = -(-low // HUGE_PAGE) * HUGE_PAGE, high // HUGE_PAGE * HUGE_PAGE
        if end > start:
            ranges.append((start, end))
    return ranges
