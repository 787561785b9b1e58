"""The default executor: forked, killable, isolated child processes, one per job.

Why not joblib or multiprocessing: a method that sleeps forever, allocates without bound,
forks, or signals its process group must cost exactly its own row. Every job therefore
runs in its own pair of forked processes (see :mod:`rippleb.isolation`): a *keeper*
(rippleb's code: new session, new PID namespace where permitted, child subreaper) and
the *worker* it forks, which runs the job with a memory limit (``RLIMIT_AS``, soft and
hard, so the job cannot lift it), with every inherited file descriptor closed but its
result pipe, and with its output going to a file. At the job's deadline, or when the job
ends, the worker and everything it started are killed.

In a local run the keepers are forked by a fork server (:mod:`rippleb.forkserver`) that
was forked before the first simulation, so no job's memory holds a truth; without a server
(a Dask worker's row, ``rippleb list``'s import probes) the keeper is forked from here.

The worker sends its result as bytes through a pipe: a tag byte (``D`` done, ``R``
raised) and the payload. The parent never unpickles what a worker sends; the payload's
format is the job's business (:mod:`rippleb.cache` encodes plain arrays). A worker that
writes more than ``max_bytes`` is killed.
"""

from __future__ import annotations

import atexit
import contextlib
import errno
import functools
import gc
import os
import resource
import select
import signal
import sys
import time
import traceback
from dataclasses import dataclass, field

from rippleb import isolation
from rippleb.registry import one_line

POLL_S = 0.2
KEEPER_GRACE_S = 5.0
DEFAULT_MAX_BYTES = 2**30


@dataclass
class Finished:
    """How a job ended: ``kind`` is ``done`` (``value`` holds its bytes), ``raised``
    (``value`` is the one-line error), ``timeout``, ``oversized`` or ``died`` (``value``
    the worker's exit code, negative for a signal)."""

    key: object
    kind: str
    value: object
    wall_s: float


@dataclass
class _Running:
    key: object
    keeper: int
    result_fd: int
    ctrl_fd: int
    started: float
    deadline: float | None
    max_bytes: int
    direct: bool = True    # the keeper is our child (else the fork server's)
    result: bytearray = field(default_factory=bytearray)
    ctrl: bytearray = field(default_factory=bytearray)
    result_eof: bool = False
    ctrl_eof: bool = False

    @property
    def ctrl_lines(self) -> list[str]:
        return bytes(self.ctrl).decode(errors="replace").splitlines()

    @property
    def worker(self) -> int | None:
        lines = self.ctrl_lines
        return int(lines[0].split()[0]) if lines else None

    @property
    def exit_code(self) -> int | None:
        lines = self.ctrl_lines
        return int(lines[1]) if len(lines) > 1 and bytes(self.ctrl).endswith(b"\n") else None


class Pool:
    """Run callables returning ``bytes`` in at most ``size`` isolated children at once.

    Parameters
    ----------
    size
        Jobs running at once.
    memory_mb
        Extra address space a worker may map beyond what it inherits [MB]; None for no limit.
    context
        Passed to every job: a job runs as ``job(context)``, or ``job()`` when None.
    server
        A :class:`rippleb.forkserver.ForkServer` to fork the keepers (it passes its own
        context); jobs must then be picklable. None forks them from this process.
    """

    def __init__(self, size: int = 1, memory_mb: float | None = None, context=None, server=None):
        self.size = size
        self.memory_mb = memory_mb
        self.context = context
        self.server = server
        self._running: list[_Running] = []

    @property
    def free(self) -> int:
        """Slots free for new jobs."""
        return self.size - len(self._running)

    @property
    def busy(self) -> bool:
        """True while a job is running."""
        return bool(self._running)

    def submit(self, key, fn, timeout: float | None = None, output: str | None = None,
               max_bytes: int | None = None) -> None:
        """Start ``fn`` (see ``context``) in an isolated worker; its stdout and stderr go to
        the file ``output`` (or /dev/null), so a chatty plugin cannot garble the CLI's output."""
        reap_exiting()
        result_r, result_w = os.pipe()
        ctrl_r, ctrl_w = os.pipe()
        try:
            if self.server is not None:
                pid = self.server.spawn(fn, result_w, ctrl_w, self.memory_mb, output)
            else:
                bound = fn if self.context is None else functools.partial(fn, self.context)
                sys.stdout.flush()
                sys.stderr.flush()
                pid = os.fork()
                if pid == 0:
                    keeper(bound, result_w, ctrl_w, self.memory_mb, output)  # never returns
        finally:  # the keeper holds the write ends now (or no keeper started)
            os.close(result_w)
            os.close(ctrl_w)
        for fd in (result_r, ctrl_r):
            os.set_blocking(fd, False)
        now = time.monotonic()
        self._running.append(_Running(key, pid, result_r, ctrl_r, now, now + timeout if timeout else None,
                                      max_bytes or DEFAULT_MAX_BYTES, direct=self.server is None))

    def wait(self) -> list[Finished]:
        """Block until at least one job ends (or passes its deadline); return those that did."""
        while True:
            finished = self._collect()
            reap_exiting()
            if finished or not self._running:
                return finished
            deadlines = [r.deadline for r in self._running if r.deadline is not None]
            # Wake at least every POLL_S: a signal caught by another thread (tqdm's
            # monitor, a timer) only runs its Python handler once the main thread wakes.
            timeout = min([POLL_S] + [max(0.0, d - time.monotonic()) for d in deadlines])
            fds = [fd for r in self._running for fd, eof in ((r.result_fd, r.result_eof),
                                                             (r.ctrl_fd, r.ctrl_eof)) if not eof]
            with contextlib.suppress(InterruptedError):
                select.select(fds, [], [], timeout)

    def kill_all(self) -> None:
        """End every running job and its processes now (used on SIGINT/SIGTERM)."""
        for run in self._running:
            _end(run)
        self._running.clear()
        reap_exiting()

    def _collect(self) -> list[Finished]:
        done, now = [], time.monotonic()
        for run in list(self._running):
            _read(run)
            result = None
            if len(run.result) > run.max_bytes:
                result = Finished(run.key, "oversized", len(run.result), now - run.started)
            elif run.exit_code is not None or run.ctrl_eof:
                _end(run, _EXITING)  # the worker is gone: drain its pipe to the end
                result = _outcome(run, now)
            elif run.deadline is not None and now >= run.deadline:
                result = Finished(run.key, "timeout", None, now - run.started)
            if result is not None:
                _end(run)
                self._running.remove(run)
                done.append(result)
        return done


def _outcome(run: _Running, now: float) -> Finished:
    wall = now - run.started
    tag, payload = bytes(run.result[:1]), bytes(run.result[1:])
    if tag == b"D":
        return Finished(run.key, "done", payload, wall)
    if tag == b"R":
        return Finished(run.key, "raised", payload.decode(errors="replace"), wall)
    code = run.exit_code
    return Finished(run.key, "died", code, wall)


def _read(run: _Running) -> None:
    for name in ("result", "ctrl"):
        fd, buf = getattr(run, f"{name}_fd"), getattr(run, name)
        if getattr(run, f"{name}_eof"):
            continue
        while len(buf) <= run.max_bytes:
            try:
                chunk = os.read(fd, 1 << 20)
            except BlockingIOError:
                break
            except OSError:
                chunk = b""
            if not chunk:
                setattr(run, f"{name}_eof", True)
                break
            buf += chunk


def _end(run: _Running, exiting: list | None = None) -> None:
    """Kill the worker (and so its namespace), let the keeper clean up, reap the keeper.

    A keeper that has reported its worker's exit has cleaned up already and has only to
    exit: with ``exiting`` given it is left to exit on its own and reaped later (added
    to ``exiting``), so the runner starts the next job instead of waiting for an exit.
    """
    if run.keeper is None:
        return
    cleaned = exiting is not None and run.exit_code is not None
    if run.exit_code is None and run.worker is not None:
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.kill(run.worker, signal.SIGKILL)
    if not run.direct:  # the fork server reaps it: only make sure it is gone
        if run.exit_code is None:
            _await_keeper_exit(run)
    elif cleaned:
        exiting.append((run.keeper, time.monotonic() + KEEPER_GRACE_S))
    else:
        _wait_keeper(run.keeper)
    # Every writer should be gone now (the keeper ended the worker's processes before it
    # reported): take what is left in the pipes (bounded in time, in case an escaped
    # process still holds one), then close them.
    give_up = time.monotonic() + 1.0
    while not (run.result_eof and (run.ctrl_eof or cleaned)) and time.monotonic() < give_up:
        _read(run)
        if len(run.result) > run.max_bytes:
            break
        open_fds = [fd for fd, eof in ((run.result_fd, run.result_eof), (run.ctrl_fd, run.ctrl_eof or cleaned))
                    if not eof]
        if open_fds:
            with contextlib.suppress(InterruptedError):
                select.select(open_fds, [], [], 0.05)
    os.close(run.result_fd)
    os.close(run.ctrl_fd)
    run.keeper = None


#: Keepers whose job has ended and that have only to exit: ``(pid, when to stop waiting)``.
#: Shared by every pool of the process (a Dask worker runs one pool per row), reaped by
#: the next pool call and at exit.
_EXITING: list[tuple[int, float]] = []


def reap_exiting(block: bool = False) -> None:
    """Reap the keepers of :data:`_EXITING` that have exited (all of them if ``block``);
    end any that overstays its grace."""
    now = time.monotonic()
    still = []
    for keeper, deadline in _EXITING:
        try:
            pid, _ = os.waitpid(keeper, os.WNOHANG)
        except ChildProcessError:  # reaped already
            continue
        if pid:
            continue
        if block or now > deadline:
            _wait_keeper(keeper, max(0.0, deadline - now))
        else:
            still.append((keeper, deadline))
    _EXITING[:] = still


atexit.register(reap_exiting, True)


def _await_keeper_exit(run: _Running, grace_s: float = KEEPER_GRACE_S) -> None:
    """Wait until a keeper that is not our child has exited (its end of the control pipe
    closes); if it has not within ``grace_s``, end its whole session."""
    deadline = time.monotonic() + grace_s
    while not run.ctrl_eof and time.monotonic() < deadline:
        with contextlib.suppress(InterruptedError):
            select.select([run.ctrl_fd], [], [], 0.05)
        _read(run)
    if not run.ctrl_eof:
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(run.keeper, signal.SIGKILL)


def _wait_keeper(keeper: int, grace_s: float = KEEPER_GRACE_S) -> None:
    """Reap ``keeper``; if it has not exited within ``grace_s``, end its whole session."""
    deadline = time.monotonic() + grace_s
    while True:
        pid, _ = os.waitpid(keeper, os.WNOHANG)
        if pid or time.monotonic() > deadline:
            break
        time.sleep(0.005)
    if not pid:  # the keeper did not finish its cleanup in time: end its whole session
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(keeper, signal.SIGKILL)
        os.waitpid(keeper, 0)


def keeper(fn, result_w: int, ctrl_w: int, memory_mb, output) -> None:
    """rippleb's own process between the runner and a job: session, namespace, cleanup.
    Runs ``fn()`` in a worker it forks; never returns."""
    try:
        _keep_inherited_pages_shared()
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        os.setsid()
        isolation.close_fds_except(result_w, ctrl_w)
        isolated = isolation.new_pid_namespace()
        isolation.become_subreaper()
        worker = os.fork()
        if worker == 0:
            # Its own process group: a worker that signals "its" group (killpg(0, ...), or
            # kill(0, ...), which is what kill(getppid()) becomes inside a PID namespace)
            # must not reach the keeper, whose death would lose the row it reports.
            os.setpgid(0, 0)
            os.close(ctrl_w)
            _worker(fn, result_w, memory_mb, output)  # never returns
        os.close(result_w)
        _write_all(ctrl_w, f"{worker} {int(isolated)}\n".encode())
        _, status = os.waitpid(worker, 0)
        if isolated:  # the kernel ended the namespace with its first process: nothing left to hunt
            isolation.reap_exited()
        else:
            isolation.end_descendants()
        _write_all(ctrl_w, f"{os.waitstatus_to_exitcode(status)}\n".encode())
    finally:
        os._exit(0)


def _worker(fn, result_w: int, memory_mb, output) -> None:
    message = b"R" + b"worker did not start"
    try:
        _keep_inherited_pages_shared()
        isolation.die_with_parent()
        isolation.close_fds_except(result_w)
        _redirect_output(output)
        _limit_memory(memory_mb)
        try:
            payload = fn()
            message = b"D" + bytes(payload)
        except BaseException as exc:  # everything a plugin can raise becomes a row status
            traceback.print_exc()
            message = b"R" + one_line(exc).encode()
        _write_all(result_w, message)
        os.close(result_w)
        sys.stdout.flush()
        sys.stderr.flush()
    finally:
        # Skip the parent's atexit handlers and buffered files (pytest, tqdm) in the child.
        os._exit(0)


def _keep_inherited_pages_shared() -> None:
    """Exclude every object inherited from the runner from this process's garbage
    collections: a collection writes to each object it visits, and so would copy, page by
    page, the whole runner's heap that the fork shares (tens of milliseconds per job)."""
    gc.freeze()


def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        try:
            n = os.write(fd, view)
        except InterruptedError:
            continue
        except OSError as exc:
            if exc.errno == errno.EPIPE:
                return
            raise
        view = view[n:]


def _redirect_output(path: str | None) -> None:
    null = os.open(os.devnull, os.O_RDONLY)
    os.dup2(null, 0)
    os.close(null)
    fd = os.open(path or os.devnull, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    os.dup2(fd, 1)
    os.dup2(fd, 2)
    os.close(fd)
    # sys.stdout/stderr may be wrappers that bypass fds 1 and 2 (pytest, IDEs): rebind them.
    sys.stdout = open(1, "w", buffering=1, closefd=False)
    sys.stderr = open(2, "w", buffering=1, closefd=False)


def _limit_memory(memory_mb: float | None) -> None:
    """Cap the address space at what the worker inherited plus ``memory_mb``.

    RLIMIT_AS counts the mappings inherited from the parent (numpy, scipy, Pinocchio
    and their thread stacks reserve much address space), so an absolute cap would be
    meaningless; the cap is relative to the size at fork time.

    Both the soft and the hard limit are set: an unprivileged process may raise its soft
    limit up to its hard one, so a soft cap alone is one ``setrlimit`` call away from
    gone (issue 25: a plugin lifted it and held 1.5 GiB under ``--memory-limit 200``).
    Lowering the hard limit cannot be undone without privileges. The call happens only
    here, in the forked worker: the keeper, the fork server and the runner keep theirs.
    """
    if memory_mb is None:
        return
    try:
        with open("/proc/self/statm") as fh:
            current = int(fh.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
        limit = current + int(memory_mb * 2**20)
        _, hard = resource.getrlimit(resource.RLIMIT_AS)
        if hard != resource.RLIM_INFINITY:
            limit = min(limit, hard)
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    except (OSError, ValueError):
        pass  # not Linux: run without a memory limit rather than refuse to run
