"""Rows on a ``dask.distributed`` cluster (``--scheduler ADDRESS`` or ``--executor dask``).

The client (the ``rippleb`` process) submits one task per row and records each row as it
comes back, in the same :class:`rippleb.engine.results.ResultsFile` as a local run: it alone
writes ``results.csv`` (atomically), so Ctrl-C, ``--resume`` and ``rippleb report`` work
unchanged. What is in flight is bounded (:data:`IN_FLIGHT_PER_THREAD` tasks per worker
thread, topped up as rows finish), so a 64 000-row sweep never floods the scheduler, and
the rows of one seed go to one worker while it has some left (:class:`_Dispatch`).

A task carries everything its row needs (:class:`rippleb.engine.executors.RowTask`: the scenario
objects, the key, the limits) and nothing from the client's disk; what a worker does with
it is :mod:`rippleb.engine.dask.worker`.

A worker that dies mid-row loses no row: the scheduler runs its task again elsewhere; a
task that has killed ``distributed.scheduler.allowed-failures`` workers comes back as an
``error`` row naming the last worker lost, marked environmental so ``--resume`` runs it
again.
"""

from __future__ import annotations

import collections
import contextlib
import logging
import time
import uuid

from rippleb import interrupts
from rippleb.engine.dask.connect import CONNECT_TIMEOUT_S, check_scheduler, lost
from rippleb.engine.dask.worker import remote_row, warm
from rippleb.errors import EnvironmentLost, InputError
from rippleb.numerics import openblas_threads
from rippleb.engine.results import ENVIRONMENT

IN_FLIGHT_PER_THREAD = 2
THREADS_REFRESH_S = 2.0
#: How often the client looks for finished rows, a signal and its scheduler [s].
POLL_S = 0.05

#: Dask settings for rippleb's clusters. With Dask's defaults an idle scheduler, nanny and
#: worker spend 1.8 %, 1.7 % and 2.9 % of a core on periodic callbacks (measured with psutil
#: over 20 s, docs/scale.md), 11 % of a core for a 2-worker cluster and 37 % for a node of 8;
#: with these, 0.3 %, 0.05 % and 0.2 %. None of them decides where, when or whether a row runs:
#: the event-loop watchdog looks 1 time a second instead of 50 (it still warns after 3 s);
#: the statistical profiler, which would sample a worker thread that only waits for its
#: row's process, is off; the system monitor's dashboard metrics and the memory monitor are
#: read every 5 s and 1 s (a row's memory is bounded by its own limit, ``rippleb.engine.process.pool``).
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
    connect_timeout
        Seconds the scheduler has to answer (``--connect-timeout``).
    """

    def __init__(self, scheduler: str | None = None, workers: int = 1,
                 connect_timeout: float = CONNECT_TIMEOUT_S):
        self.scheduler = scheduler
        self.workers = workers
        self.connect_timeout = connect_timeout

    def check(self) -> None:
        """Raise :class:`~rippleb.errors.InputError` (one line) unless the scheduler answers;
        the runner calls this before it claims the run directory."""
        if self.scheduler is not None:
            check_scheduler(self.scheduler, self.connect_timeout)

    def run(self, tasks: list, record) -> None:
        """Run ``tasks`` (:class:`rippleb.engine.executors.RowTask`); call ``record(key, fields)`` in
        this process for each row as it finishes.

        Runs with signals held (:mod:`rippleb.interrupts`): Dask's blocking calls are made
        with signals raised, the rows are awaited by polling. Raises
        :class:`~rippleb.errors.EnvironmentLost` if the scheduler is lost.
        """
        if not tasks:
            return
        client = None
        try:
            with contextlib.ExitStack() as stack:
                stack.callback(logging.disable, logging.NOTSET)
                with interrupts.raising():  # starting a cluster, connecting: Dask's own waits
                    client = stack.enter_context(self._client())
                stack.push(_quiet_on_failure(client))   # runs before the client closes
                _await_workers(client)
                with interrupts.raising():
                    warm_workers(client)
                _stream(client, tasks, record)
        except Exception as exc:  # noqa: BLE001 - a lost scheduler surfaces as many types
            if client is None or not lost(client):
                raise
            raise EnvironmentLost(f"{self._name()}: lost the scheduler mid-run ({_one_line(exc)[:160]})") from None

    def _name(self) -> str:
        return f"--scheduler {self.scheduler}" if self.scheduler is not None else "--executor dask"

    @contextlib.contextmanager
    def _client(self):
        """A connected ``Client``: to the scheduler, or to a ``LocalCluster`` it owns."""
        import dask
        from distributed import Client, LocalCluster

        if self.scheduler is None:
            # Errors only: a cancelled task's warnings (after Ctrl-C) are not the user's business.
            # The nannies hand the configuration they were made under to their workers.
            with dask.config.set(QUIET_CONFIG):
                # Held: a cluster cut short while it starts is left to Dask's atexit, which
                # fails on it with a traceback. It starts within seconds, then goes.
                with interrupts.held(), _sigint_blocked():
                    cluster = LocalCluster(n_workers=self.workers, threads_per_worker=1, processes=True,
                                           dashboard_address=":0", silence_logs=logging.ERROR)
                with cluster:
                    with interrupts.held():
                        client = Client(cluster)
                    with client:
                        interrupts.check_interrupted()
                        yield client
            return
        try:
            client = Client(self.scheduler, timeout=self.connect_timeout)
        except Exception as exc:  # noqa: BLE001 - it answered check() a moment ago: it is lost
            raise EnvironmentLost(f"{self._name()}: cannot connect any more ({_one_line(exc)[:160]})") from None
        with client:
            yield client


@contextlib.contextmanager
def _sigint_blocked():
    """Block SIGINT in this thread while the local cluster starts: the thread Dask starts
    for its event loop, and the worker processes that thread spawns, inherit the mask. So a
    Ctrl-C in the terminal, which reaches the whole process group, reaches only this process
    (which ends the cluster), not the workers, which would each print a traceback. Here the
    signal waits, and is handled once the cluster has started.

    multiprocessing's resource tracker is started first: starting it unblocks SIGINT in the
    calling thread (``SIG_UNBLOCK``, not the mask it found), which would undo this.
    """
    import signal
    from multiprocessing import resource_tracker

    resource_tracker.ensure_running()
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def _quiet_on_failure(client):
    """An exit callback: if the run ends by an exception (Ctrl-C, a lost scheduler),
    silence logging while the client and its cluster close. Dask logs errors with
    tracebacks as they go (broadcasts cut short, a reconnection given up), and the user
    gets the one line that says what happened."""
    def quiet(exc_type, exc, tb) -> bool:
        if exc_type is not None or lost(client):
            logging.disable(logging.CRITICAL)
        return False
    return quiet


def _await_workers(client) -> None:
    """Wait until a worker has joined (on a batch system they may queue for hours),
    looking for a signal and for the scheduler between short waits."""
    while True:
        interrupts.check_interrupted()
        try:
            client.wait_for_workers(1, timeout=1.0)
            return
        except TimeoutError:
            if lost(client):
                raise


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
    client.run(warm, openblas_threads())


def _stream(client, tasks: list, record) -> None:
    """Submit ``tasks`` a few at a time and record each row as it comes back, until all are
    recorded, a signal arrives (``KeyboardInterrupt``) or the scheduler is lost (the rows
    then in flight are left to ``--resume``)."""
    from distributed import as_completed

    dispatch = _Dispatch(client, tasks)
    stream = as_completed()
    blas = openblas_threads()
    in_flight: dict = {}

    def top_up():
        if dispatch.left() and lost(client):
            raise ConnectionError("the scheduler stopped answering")
        for task, worker in dispatch.take():
            future = client.submit(remote_row, task, blas, key=f"rippleb-row-{uuid.uuid4().hex}", pure=False,
                                   workers=[worker], allow_other_workers=True)
            in_flight[future] = (task, worker)
            stream.add(future)
    try:
        top_up()
        while in_flight:
            interrupts.check_interrupted()
            batch = stream.next_batch(block=False)
            if not batch:
                if lost(client):
                    raise ConnectionError("the scheduler stopped answering")
                time.sleep(POLL_S)
            for future in batch:
                task, worker = in_flight.pop(future)
                dispatch.done(worker)
                record(task.key, _fields(future))
                future.release()
            if batch:
                top_up()
    finally:
        if in_flight and not lost(client):  # Ctrl-C or an error: the rows not recorded are left to --resume
            with contextlib.suppress(Exception):
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

    def left(self) -> bool:
        """True while some task has not been handed out."""
        return any(self.groups.values())

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
