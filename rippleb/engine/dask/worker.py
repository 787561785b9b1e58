"""What a Dask worker does with a row (the client side is :mod:`rippleb.engine.dask.executor`).

The worker recomputes the row's simulations from the seed (the simulator is deterministic,
so the accuracy columns are bit for bit those of a local run) and runs the row with
:func:`rippleb.engine.executors.run_task`, i.e. with the local run's own pool: the method's fit and
steps run in their own isolated process (session, PID namespace, memory limit, timeout),
never see the truth, and a crash is the row's status. As locally, those processes are
forked by a fork server (:mod:`rippleb.engine.process.forkserver`), one per worker process, started
before the worker's first row, so no row's memory holds a truth the worker keeps. Scoring
happens in the task's process (rippleb's code). Simulations and fits are kept per worker
process in a private temporary directory (:data:`MEMO_CASES` cases at most), so the rows of
one case that land on one worker simulate it once.
"""

from __future__ import annotations

import atexit
import collections
import contextlib
import functools
import shutil
import tempfile
import threading
import uuid

from rippleb.numerics import openblas_threads

MEMO_CASES = 16

# This worker process's state (one per process, shared by its task threads).
_memo_lock = threading.Lock()
_memo: collections.OrderedDict = collections.OrderedDict()
_memo_root: list = []
_rows = threading.Condition()   # guards the fork server and the count of rows running
_server: list = []              # this worker process's fork server, once started
_running = [0]                  # rows running in this process


def warm(blas_threads: int | None = None) -> None:
    """Load what rows need and start this worker's fork server (run on each worker by
    :func:`rippleb.engine.dask.executor.warm_workers`)."""
    _load_modules()
    _enter_row(blas_threads)  # start this worker's fork server now, from its main thread
    _leave_row()


def _default_malloc() -> None:
    """Undo, in this process and so in the rows' processes forked from it, the
    ``MALLOC_TRIM_THRESHOLD_`` that Dask's nanny puts in its workers' environment
    (``distributed.nanny.pre-spawn-environ``).

    Setting it fixes glibc's mmap threshold at 128 KiB, so every array of a log's length
    (hundreds of kB) is mapped, faulted in page by page and unmapped again, where a local
    run's processes keep reusing their heap (glibc raises the threshold up to 32 MiB as
    large blocks are freed). That cost the rows' processes a third of their system CPU and
    the worker, which unpacks and scores every row, more than half of its CPU per task
    (docs/scale.md). The worker and its rows get the ceiling of glibc's default behaviour:
    a worker keeps up to 64 MiB of freed heap instead of returning it at once.
    """
    import ctypes
    import ctypes.util
    import os

    if "MALLOC_TRIM_THRESHOLD_" not in os.environ:
        return
    del os.environ["MALLOC_TRIM_THRESHOLD_"]
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        m_trim_threshold, m_mmap_threshold = -1, -3      # <malloc.h>
        libc.mallopt(m_mmap_threshold, 32 << 20)
        libc.mallopt(m_trim_threshold, 64 << 20)
    except (OSError, AttributeError):
        pass  # not glibc: nothing to undo


def _load_modules() -> None:
    """The modules every row needs, loaded in the worker and its fork server."""
    import rippleb.scoring.metrics  # noqa: F401 - loaded for the forks to inherit
    import rippleb.simulator.simulation  # noqa: F401 - with the joint's compiled kernels

    _registry().load_builtins()


def remote_row(task, blas_threads: int | None = None) -> dict:
    """The task run on a worker: one row, as :func:`rippleb.engine.executors.run_task` runs it.

    ``blas_threads`` is the client's OpenBLAS thread count: dask's nanny starts workers
    with ``OPENBLAS_NUM_THREADS=1`` (``distributed.nanny.pre-spawn-environ``), and a BLAS
    call split over another number of threads sums in another order, so a method using
    BLAS would differ from a local run in its last bits. The worker's fork server is started
    with the client's count, and the row's processes inherit it.

    :class:`rippleb.engine.process.pool.Pool` starts each job with ``os.fork``, not ``multiprocessing``:
    a dask worker process is *daemonic* (its nanny starts it with ``daemon=True``) and
    ``multiprocessing.Process.start`` refuses children of a daemonic process ("daemonic
    processes are not allowed to have children"), but that check is multiprocessing's
    own; a plain fork is not subject to it, and the pool's keeper then reaps and kills
    everything the row started, as locally. The forked keeper is single-threaded (only
    the forking thread survives a fork), which its PID namespace needs.
    """
    from rippleb.engine.executors import run_task

    server = _enter_row(blas_threads)
    try:
        cache = _task_dir()
        with _memo_lock:
            memo = dict(_memo)
        try:
            return run_task(task, cache, _registry(), memo, server=server)
        finally:
            with _memo_lock:
                _remember(memo)
    finally:
        _leave_row()


def _enter_row(blas_threads: int | None = None):
    """Count a row as running here; the fork server its jobs are forked from.

    The server must never inherit a truth: it is started (or, if it died or runs another
    BLAS thread count, started again) only while no row runs in this process, after the
    memo's simulations are dropped. Its jobs inherit its BLAS thread count, the client's.
    """
    from rippleb.engine.process.forkserver import ForkServer

    with _rows:
        while not (_server and _server[0].alive() and _server[1] == blas_threads):
            if _running[0] == 0:
                if _server:  # it died or has the wrong count: let it go
                    _server[0].close()
                if blas_threads:
                    openblas_threads(blas_threads)
                _default_malloc()  # the worker scores every row; its server forks inherit it
                _forget_memo()
                _server[:] = [ForkServer.start(_registry(), preload=_load_modules), blas_threads]
                break
            _rows.wait()   # rows still running here hold truths: start it after them
        _running[0] += 1
        return _server[0]


def _leave_row() -> None:
    with _rows:
        _running[0] -= 1
        _rows.notify_all()


def _forget_memo() -> None:
    """Drop every simulation and fit the memo keeps (and their files)."""
    with _memo_lock:
        for key in list(_memo):
            _drop(key)


def _drop(key) -> None:
    """Take ``key`` out of the memo and delete its file: a case's simulated log (its value
    a tuple led by the artefact) or a fitted method (its fit info)."""
    import os

    value = _memo.pop(key)
    path = value[0].path if isinstance(value, tuple) else value["fitted"]["path"]
    with contextlib.suppress(OSError):
        os.unlink(path)


@functools.lru_cache(maxsize=1)
def _registry():
    """The methods this worker can load (its own environment's entry points), found once."""
    from rippleb.registry import Registry

    return Registry.discover()


def _task_dir():
    """A fresh directory for one task's files, under this process's private root."""
    from pathlib import Path

    with _memo_lock:
        if not _memo_root:
            root = tempfile.mkdtemp(prefix="rippleb-worker-")
            atexit.register(shutil.rmtree, root, ignore_errors=True)
            _memo_root.append(root)
    path = Path(_memo_root[0]) / uuid.uuid4().hex
    path.mkdir()
    return path


def _remember(memo: dict) -> None:
    """Keep the newest :data:`MEMO_CASES` cases (and the fits on them); delete the rest's files."""
    for key, value in memo.items():
        _memo[key] = value
        _memo.move_to_end(key)
    cases = [k for k in _memo if hasattr(k, "role")]
    for old in cases[:max(0, len(cases) - MEMO_CASES)]:
        _drop(old)
        for fit in [k for k in _memo if getattr(k, "calibration", None) == old]:
            _drop(fit)

