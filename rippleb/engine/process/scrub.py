"""What a forked process inherits from the runner that a method must not read: the runner's
command line and its environment.

A fork copies the whole process: ``/proc/self/cmdline`` (the runner's, which may name
``--salt-file FILE``), ``/proc/self/environ`` and ``os.environ`` (the user's exported
variables: a cloud key, an SSH agent's socket; issue 41 found a method reading an exported
secret). Both are wiped in the fork server when it starts, so no job forked from it inherits
them, and again in each method's worker, which a pool without a server forks from the
runner itself: the original blocks are zeroed in place, and ``os.environ`` keeps only
:data:`KEPT` and :data:`KEPT_PREFIXES`, the variables that set how the libraries compute.
"""

from __future__ import annotations

import ctypes
import functools
import os
import sys

#: Variables a method's process keeps: where programs are, the home directory's path (its
#: files stay unreadable), the language and the time zone.
KEPT = ("PATH", "HOME", "LANG", "LANGUAGE", "TZ", "TMPDIR", "PYTHONHASHSEED", "PYTHONPATH")
#: ... and the families that set the numeric libraries and rippleb itself (its numeric paths,
#: docs/reproducibility.md), so a row computes as it would anywhere else.
KEPT_PREFIXES = ("LC_", "OMP_", "OPENBLAS_", "GOTO", "MKL_", "NUMBA_", "NUMPY_", "MALLOC_", "RIPPLEB_")
#: Offset of a ``bytes`` object's first byte from its address (CPython's ``ob_sval``).
_BYTES_DATA = sys.getsizeof(b"") - 1


def wipe_command_line() -> None:
    """Zero this process's command line (``/proc/self/cmdline``): a forked worker inherits
    the runner's, which names ``--salt-file FILE`` in a resumed sealed run. The runner's
    own copy is untouched: the worker's pages are its own once written."""
    _zero_block(45)   # arg_start, arg_end: fields 48, 49 of proc(5)


def scrub_environment() -> None:
    """Keep only :data:`KEPT` and :data:`KEPT_PREFIXES` in ``os.environ``; zero the bytes of
    every other value where Python holds them and the original environment block
    (``/proc/self/environ``), so neither an environment listing nor a search of this
    process's memory finds them."""
    data = getattr(os.environ, "_data", None)
    if isinstance(data, dict):
        for key, value in list(data.items()):
            name = key.decode(errors="replace") if isinstance(key, bytes) else str(key)
            if name in KEPT or name.startswith(KEPT_PREFIXES):
                continue
            if isinstance(value, bytes) and len(value) > 1:   # one-byte objects are shared by the interpreter
                ctypes.memset(id(value) + _BYTES_DATA, 0, len(value))
            os.environ.pop(name, None)
    for name, value in list(os.environ.items()):
        os.putenv(name, value)   # the C library's copy of each kept one, out of the block zeroed next
    _zero_block(47)   # env_start, env_end: fields 50, 51 of proc(5)


def _zero_block(index: int) -> None:
    """Zero the memory between the two addresses at fields ``index`` and ``index + 1`` of
    ``/proc/self/stat`` counted after the command name (:func:`_blocks`)."""
    start, end = _blocks().get(index, (0, 0))
    if 0 < start < end:
        ctypes.memset(start, 0, end - start)


@functools.cache
def _blocks() -> dict[int, tuple[int, int]]:
    """Where this process's command line and environment lie: read once, in the process
    that imports this module, and inherited by each fork, in which they lie at the same
    addresses (reading ``/proc/self/stat`` in a fresh fork of the runner cost 3 ms)."""
    try:
        with open("/proc/self/stat", "rb") as fh:
            fields = fh.read().rsplit(b")", 1)[1].split()
        return {index: (int(fields[index]), int(fields[index + 1])) for index in (45, 47)}
    except (OSError, ValueError, IndexError):
        return {}


_blocks()
