"""A pool of forked child processes, one per job, each of which can be killed.

Why not joblib: a joblib/loky timeout aborts the whole ``Parallel`` call and cannot kill
one hung worker while the others go on, and loky pickles the arguments of every task.
A method that sleeps forever or allocates without bound must cost exactly one row, so
every job here is its own ``fork``-ed process: it inherits the parent's memory (the
scenario objects, the registry) without pickling, gets a memory limit with
``RLIMIT_AS``, ignores SIGINT (the parent decides), and is ended with SIGKILL at its
deadline. Forking costs a few milliseconds per job, small next to one row.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import sys
import time
import traceback
from dataclasses import dataclass
from multiprocessing.connection import wait as wait_any

from rippleb.registry import one_line

POLL_S = 0.2


@dataclass
class Finished:
    """How a job ended: ``kind`` is ``done`` (``value`` holds its result), ``raised``
    (``value`` is the one-line error), ``timeout`` or ``died`` (``value`` the exit code)."""

    key: object
    kind: str
    value: object
    wall_s: float


@dataclass
class _Running:
    key: object
    process: multiprocessing.Process
    conn: object
    started: float
    deadline: float | None


class Pool:
    """Run callables in at most ``size`` forked children at once.

    Parameters
    ----------
    size
        Children running at once.
    memory_mb
        Extra address space a child may map beyond what it inherits [MB]; None for no limit.
    """

    def __init__(self, size: int = 1, memory_mb: float | None = None):
        self.size = size
        self.memory_mb = memory_mb
        self._ctx = multiprocessing.get_context("fork")
        self._running: list[_Running] = []

    @property
    def free(self) -> int:
        """Slots free for new jobs."""
        return self.size - len(self._running)

    @property
    def busy(self) -> bool:
        """True while a child is running."""
        return bool(self._running)

    def submit(self, key, fn, timeout: float | None = None, output: str | None = None) -> None:
        """Start ``fn()`` in a child; its stdout and stderr go to the file ``output`` (or
        /dev/null), so a chatty plugin cannot garble the CLI's output."""
        receiver, sender = self._ctx.Pipe(duplex=False)
        process = self._ctx.Process(target=_child, args=(sender, fn, self.memory_mb, output),
                                    daemon=True)
        process.start()
        sender.close()
        now = time.monotonic()
        deadline = now + timeout if timeout else None
        self._running.append(_Running(key, process, receiver, now, deadline))

    def wait(self) -> list[Finished]:
        """Block until at least one job ends (or passes its deadline); return those that did."""
        while True:
            finished = self._collect()
            if finished or not self._running:
                return finished
            deadlines = [r.deadline for r in self._running if r.deadline is not None]
            # Wake at least every POLL_S: a signal caught by another thread (tqdm's
            # monitor, a timer) only runs its Python handler once the main thread wakes.
            timeout = min([POLL_S] + [max(0.0, d - time.monotonic()) for d in deadlines])
            handles = [r.conn for r in self._running] + [r.process.sentinel for r in self._running]
            wait_any(handles, timeout)

    def kill_all(self) -> None:
        """End every running child now (used on SIGINT/SIGTERM)."""
        for run in self._running:
            _kill(run)
        self._running.clear()

    def _collect(self) -> list[Finished]:
        done, now = [], time.monotonic()
        for run in list(self._running):
            result = None
            if run.conn.poll():
                try:
                    kind, value = run.conn.recv()
                    result = Finished(run.key, kind, value, now - run.started)
                except (EOFError, OSError):
                    pass
            if result is None and not run.process.is_alive():
                result = Finished(run.key, "died", run.process.exitcode, now - run.started)
            if result is None and run.deadline is not None and now >= run.deadline:
                result = Finished(run.key, "timeout", None, now - run.started)
            if result is not None:
                _kill(run)
                self._running.remove(run)
                done.append(result)
        return done


def _kill(run: _Running) -> None:
    if run.process.is_alive():
        run.process.kill()
    run.process.join()
    run.conn.close()


def _child(conn, fn, memory_mb, output) -> None:
    # The parent owns interruption: it kills children, then writes what finished.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    try:
        _redirect_output(output)
        _limit_memory(memory_mb)
        message = ("done", fn())
    except BaseException as exc:  # everything a plugin can raise becomes a row status
        traceback.print_exc()
        message = ("raised", one_line(exc))
    try:
        conn.send(message)
        conn.close()
        sys.stdout.flush()
        sys.stderr.flush()
    finally:
        # Skip the parent's atexit handlers and buffered files (pytest, tqdm) in the child.
        os._exit(0)


def _redirect_output(path: str | None) -> None:
    fd = os.open(path or os.devnull, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    sys.stdout.flush()
    sys.stderr.flush()
    os.dup2(fd, 1)
    os.dup2(fd, 2)
    os.close(fd)
    # sys.stdout/stderr may be wrappers that bypass fds 1 and 2 (pytest, IDEs): rebind them.
    sys.stdout = open(1, "w", buffering=1, closefd=False)
    sys.stderr = open(2, "w", buffering=1, closefd=False)


def _limit_memory(memory_mb: float | None) -> None:
    """Cap the address space at what the child inherited plus ``memory_mb``.

    RLIMIT_AS counts the mappings inherited from the parent (numpy, scipy, Pinocchio
    and their thread stacks reserve much address space), so an absolute cap would be
    meaningless; the cap is relative to the size at fork time.
    """
    if memory_mb is None:
        return
    try:
        import resource

        with open("/proc/self/statm") as fh:
            current = int(fh.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
        limit = current + int(memory_mb * 2**20)
        _, hard = resource.getrlimit(resource.RLIMIT_AS)
        if hard != resource.RLIM_INFINITY:
            limit = min(limit, hard)
        resource.setrlimit(resource.RLIMIT_AS, (limit, hard))
    except (OSError, ValueError, ImportError):
        pass  # not Linux: run without a memory limit rather than refuse to run
