"""Rows on a ``dask.distributed`` cluster (``--scheduler ADDRESS`` or ``--executor dask``).

The client (the ``rippleb`` process) submits one task per row and records each row as it
comes back, in the same :class:`rippleb.results.ResultsFile` as a local run: it alone
writes ``results.csv`` (atomically), so Ctrl-C, ``--resume`` and ``rippleb report`` work
unchanged. What is in flight is bounded (:data:`IN_FLIGHT_PER_THREAD` tasks per worker
thread, topped up as rows finish), so a 64 000-row sweep never floods the scheduler, and
the rows of one seed go to one worker while it has some left (:class:`_Dispatch`).

A task carries everything its row needs (:class:`rippleb.executors.RowTask`: the scenario
objects, the key, the limits) and nothing from the client's disk: the worker recomputes
the row's simulations from the seed (the simulator is deterministic, so the accuracy
columns are bit for bit those of a local run) and runs the row with
:func:`rippleb.executors.run_task`, i.e. with the local run's own pool: the method's fit and
steps run in their own isolated process (session, PID namespace, memory limit, timeout),
never see the truth, and a crash is the row's status. As locally, those processes are
forked by a fork server (:mod:`rippleb.forkserver`), one per worker process, started
before the worker's first row, so no row's memory holds a truth the worker keeps.
Scoring happens in the task's process (rippleb's code). Simulations and fits are kept per worker process in a private
temporary directory (:data:`MEMO_CASES` cases at most), so the rows of one case that land
on one worker simulate it once.

A worker that dies mid-row loses no row: the scheduler runs its task again elsewhere; a
task that has killed ``distributed.scheduler.allowed-failures`` workers comes back as an
``error`` row naming the last worker lost, marked environmental so ``--resume`` runs it
again.
"""

from __future__ import annotations

import atexit
import collections
import contextlib
import functools
import logging
import shutil
import tempfile
import threading
import time
import uuid

from rippleb.errors import InputError
from rippleb.results import ENVIRONMENT

IN_FLIGHT_PER_THREAD = 2
MEMO_CASES = 16
CONNECT_TIMEOUT_S = 10
THREADS_REFRESH_S = 2.0

#: Dask settings for rippleb's clusters. With Dask's defaults an idle scheduler, nanny and
#: worker spend 1.8 %, 1.7 % and 2.9 % of a core on periodic callbacks (measured with psutil
#: over 20 s, docs/scale.md), 11 % of a core for a 2-worker cluster and 37 % for a node of 8;
#: with these, 0.3 %, 0.05 % and 0.2 %. None of them decides where, when or whether a row runs:
#: the event-loop watchdog looks 1 time a second instead of 50 (it still warns after 3 s);
#: the statistical profiler, which would sample a worker thread that only waits for its
#: row's process, is off; the system monitor's dashboard metrics and the memory monitor are
#: read every 5 s and 1 s (a row's memory is bounded by its own limit, ``rippleb.pool``).
QUIET_CONFIG = {
    "distributed.admin.tick.interval": "1s",
    "distributed.worker.profile.enabled": False,
    "distributed.admin.system-monitor.interval": "5s",
    "distributed.worker.memory.monitor-interval": "1s",
}


def quiet_environment() -> dict[str, str]:
    """:data:`QUIET_CONFIG` as the ``DASK_*`` environment variables that ``dask scheduler`` and
    ``dask worker`` read at start (``distributed.admin.tick.interval`` becomes
    ``DASK_DISTRIBUTED__ADMIN__TICK__INTERVAL``)."""
    return {"DASK_" + key.upper().replace(".", "__").replace("-", "_"): str(value)
            for key, value in QUIET_CONFIG.items()}


class DaskExecutor:
    """Run whole rows on a dask.distributed cluster.

    Parameters
    ----------
    scheduler
        Address of a running scheduler (``tcp://host:8786``), or None to start a
        ``LocalCluster`` for the run (processes, one thread each).
    workers
        Worker processes of the local cluster (ignored with ``scheduler``).
    """

    def __init__(self, scheduler: str | None = None, workers: int = 1):
        self.scheduler = scheduler
        self.workers = workers

    def run(self, tasks: list, record) -> None:
        """Run ``tasks`` (:class:`rippleb.executors.RowTask`); call ``record(key, fields)`` in
        this process for each row as it finishes."""
        if not tasks:
            return
        with self._client() as client:
            client.wait_for_workers(1)
            warm_workers(client)
            _stream(client, tasks, record)

    @contextlib.contextmanager
    def _client(self):
        import dask
        from distributed import Client, LocalCluster

        if self.scheduler is None:
            # Errors only: a cancelled task's warnings (after Ctrl-C) are not the user's business.
            # The nannies hand the configuration they were made under to their workers.
            with dask.config.set(QUIET_CONFIG), \
                    LocalCluster(n_workers=self.workers, threads_per_worker=1, processes=True,
                                 dashboard_address=":0", silence_logs=logging.ERROR) as cluster, \
                    Client(cluster) as client:
                yield client
            return
        try:
            client = Client(self.scheduler, timeout=CONNECT_TIMEOUT_S)
        except (OSError, TimeoutError, ValueError) as exc:
            raise InputError(f"--scheduler {self.scheduler}: cannot connect ({type(exc).__name__}: "
                             f"{str(exc).splitlines()[0] if str(exc) else 'no answer'})") from None
        with client:
            yield client


def warm_workers(client) -> None:
    """Have each worker of the cluster load what its rows need and start its fork server
    before its first row.

    A row's fit and steps run in processes forked by the worker's fork server, so what
    the server has loaded they inherit for free, and what it has not, each of them loads
    again. The built-in methods (with their compiled kernels), the simulator and the
    metrics are rippleb's own code, so loading them gives a method's process nothing it
    would not have had; a plugin method is still imported only in the processes that run
    it. A worker that joins later does both with its first row.
    """
    client.run(_warm, openblas_threads())


def _warm(blas_threads: int | None = None) -> None:
    _load_modules()
    _enter_row(blas_threads)  # start this worker's fork server now, from its main thread
    _leave_row()


def _prepare_server() -> None:
    """In the fork server: the heap as a process started without Dask's nanny has it (the
    worker has undone that already; a server started otherwise still needs it), and the
    modules every row needs."""
    _default_malloc()
    _load_modules()


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
    import rippleb.metrics  # noqa: F401 - loaded for the forks to inherit
    import rippleb.simulator.simulation  # noqa: F401 - with the joint's compiled kernels

    _registry().load_builtins()


def _stream(client, tasks: list, record) -> None:
    from distributed import as_completed

    from rippleb.scheduler import check_interrupted

    client.wait_for_workers(1)
    dispatch = _Dispatch(client, tasks)
    stream = as_completed()
    blas = openblas_threads()
    in_flight: dict = {}

    def top_up():
        for task, worker in dispatch.take():
            future = client.submit(remote_row, task, blas, key=f"rippleb-row-{uuid.uuid4().hex}", pure=False,
                                   workers=[worker], allow_other_workers=True)
            in_flight[future] = (task, worker)
            stream.add(future)
    try:
        top_up()
        for future in stream:
            check_interrupted()
            task, worker = in_flight.pop(future)
            dispatch.done(worker)
            record(task.key, _fields(future))
            future.release()
            top_up()
    finally:
        if in_flight:  # Ctrl-C or an error: the rows not recorded are left to --resume
            client.cancel(list(in_flight))


class _Dispatch:
    """Which row goes where next: at most :data:`IN_FLIGHT_PER_THREAD` tasks per worker thread
    in flight, and the rows of one seed to one worker while it has some left.

    The rows of a seed share its calibration log and the fits on it, and the rows of a
    scored case its simulation; a worker's memo reuses them only if they land there. So a
    worker takes the next row of the seed it owns, else the next seed no one owns, else a
    row of the seed with the most rows left (the tail of a run, rather than idling). The
    placement is a preference (``allow_other_workers``): the scheduler still moves a task
    whose worker is lost.
    """

    def __init__(self, client, tasks: list):
        self.client = client
        self.groups: dict = {}
        for task in tasks:
            self.groups.setdefault(task.key.seed, collections.deque()).append(task)
        self.owner: dict = {}
        self.busy: collections.Counter = collections.Counter()
        self.threads: dict = {}
        self.read_at = -1e9

    def take(self) -> list[tuple]:
        """``(task, worker address)`` pairs to submit now."""
        self._refresh()
        picked = []
        for worker, threads in self.threads.items():
            while self.busy[worker] < IN_FLIGHT_PER_THREAD * threads:
                task = self._next_for(worker)
                if task is None:
                    break
                self.busy[worker] += 1
                picked.append((task, worker))
        return picked

    def done(self, worker: str) -> None:
        self.busy[worker] -= 1

    def _next_for(self, worker: str):
        mine = [g for g, w in self.owner.items() if w == worker and self.groups.get(g)]
        if not mine:
            free = [g for g, rows in self.groups.items() if rows and self.owner.get(g) not in self.threads]
            if free:
                self.owner[free[0]] = worker
                mine = free[:1]
        if not mine:
            left = [g for g, rows in self.groups.items() if rows]
            if not left:
                return None
            mine = [max(left, key=lambda g: len(self.groups[g]))]
        return self.groups[mine[0]].popleft()

    def _refresh(self) -> None:
        """Re-read the workers (they may join or leave during a run) every few seconds."""
        if time.monotonic() - self.read_at > THREADS_REFRESH_S:
            self.threads = {w: max(1, n) for w, n in self.client.nthreads().items()}
            self.read_at = time.monotonic()


def _fields(future) -> dict:
    """The row's fields, or the reason the cluster could not produce them (one line)."""
    from distributed import KilledWorker

    if future.status == "finished":
        return future.result()
    if future.status != "error":  # cancelled or lost: the cluster, not the row, failed
        return {"status": "error", "message": f"{ENVIRONMENT}the cluster {future.status} the row's "
                                              f"task (scheduler lost?)"}
    exc = future.exception()
    if isinstance(exc, KilledWorker):
        return {"status": "error", "message": f"{ENVIRONMENT}dask worker lost: {_one_line(exc)}"[:500]}
    return {"status": "error", "message": f"dask task failed: {_one_line(exc)}"[:500]}


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


# ----------------------------------------------------------------------------- on the worker

_memo_lock = threading.Lock()
_memo: collections.OrderedDict = collections.OrderedDict()
_memo_root: list = []
_rows = threading.Condition()   # guards the fork server and the count of rows running
_server: list = []              # this worker process's fork server, once started
_running = [0]                  # rows running in this process


def remote_row(task, blas_threads: int | None = None) -> dict:
    """The task run on a worker: one row, as :func:`rippleb.executors.run_task` runs it.

    ``blas_threads`` is the client's OpenBLAS thread count: dask's nanny starts workers
    with ``OPENBLAS_NUM_THREADS=1`` (``distributed.nanny.pre-spawn-environ``), and a BLAS
    call split over another number of threads sums in another order, so a method using
    BLAS would differ from a local run in its last bits. The worker's fork server is started
    with the client's count, and the row's processes inherit it.

    :class:`rippleb.pool.Pool` starts each job with ``os.fork``, not ``multiprocessing``:
    a dask worker process is *daemonic* (its nanny starts it with ``daemon=True``) and
    ``multiprocessing.Process.start`` refuses children of a daemonic process ("daemonic
    processes are not allowed to have children"), but that check is multiprocessing's
    own; a plain fork is not subject to it, and the pool's keeper then reaps and kills
    everything the row started, as locally. The forked keeper is single-threaded (only
    the forking thread survives a fork), which its PID namespace needs.
    """
    from rippleb.executors import run_task

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
    from rippleb.forkserver import ForkServer

    with _rows:
        while not (_server and _server[0].alive() and _server[1] == blas_threads):
            if _running[0] == 0:
                if _server:  # it died or has the wrong count: let it go
                    _server[0].close()
                if blas_threads:
                    openblas_threads(blas_threads)
                _default_malloc()  # before the server's fork: both unpack and score logs
                _forget_memo()
                _server[:] = [ForkServer.start(_registry(), preload=_prepare_server), blas_threads]
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


def openblas_threads(set_to: int | None = None) -> int | None:
    """The thread count of the OpenBLAS libraries numpy and scipy loaded (None if none),
    after setting it to ``set_to`` if given (as threadpoolctl does, without the dependency)."""
    import ctypes

    import numpy  # noqa: F401 - load both BLAS libraries before reading or setting them
    import scipy.linalg  # noqa: F401

    counts = []
    for path in _loaded_openblas():
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for suffix in ("64_", ""):
            getter = getattr(lib, f"scipy_openblas_get_num_threads{suffix}", None) \
                or getattr(lib, f"openblas_get_num_threads{suffix}", None)
            setter = getattr(lib, f"scipy_openblas_set_num_threads{suffix}", None) \
                or getattr(lib, f"openblas_set_num_threads{suffix}", None)
            if getter is None or setter is None:
                continue
            if set_to is not None:
                setter(ctypes.c_int(int(set_to)))
            counts.append(int(getter()))
            break
    return max(counts) if counts else None


def _loaded_openblas() -> list[str]:
    try:
        with open("/proc/self/maps") as fh:
            paths = {line.split()[-1] for line in fh if "/" in line}
    except OSError:
        return []
    return sorted(p for p in paths if "openblas" in p.rsplit("/", 1)[-1].lower())
