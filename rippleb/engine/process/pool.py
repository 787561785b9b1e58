"""The default executor: forked, killable, isolated child processes, one per job.

Why not joblib or multiprocessing: a method that sleeps forever, allocates without bound,
forks, or signals its process group must cost exactly its own row. Every job therefore
runs in its own pair of forked processes (:mod:`rippleb.engine.process.keeper`, :mod:`rippleb.engine.process.isolation`):
a *keeper* (rippleb's code: new session, new PID namespace where permitted, child
subreaper) and the *worker* it forks, which runs the job with a memory limit
(``RLIMIT_AS``, soft and hard, so the job cannot lift it), with every inherited file
descriptor closed but its result pipe, and with
its output going to a file. At the job's deadline, or when the job ends, the worker and
everything it started are killed.

No wait here is unbounded, and none ignores Ctrl-C or SIGTERM (:mod:`rippleb.interrupts`):
:meth:`Pool.wait` polls for them, a job is started and ended with signals held, so none
is ever half started or half ended, and :meth:`Pool.kill_all` ends every job within a
few seconds, even one whose keeper is stuck.

In a local run the keepers are forked by a fork server (:mod:`rippleb.engine.process.forkserver`) that
was forked before the first simulation, so no job's memory holds a truth; without a server
(a Dask worker's row, ``rippleb list``'s import probes) the keeper is forked from here.

The worker sends its result as bytes through a pipe: a tag byte (``D`` done, ``R``
raised) and the payload. The parent never unpickles what a worker sends; the payload's
format is the job's business (:mod:`rippleb.engine.cache` encodes plain arrays). A worker that
writes more than ``max_bytes`` is killed.
"""

from __future__ import annotations

import contextlib
import os
import re
import select
import signal
import sys
import time
from dataclasses import dataclass, field

from rippleb import interrupts
from rippleb.engine.process.joblog import write_all
from rippleb.engine.process.keeper import Bound, keeper
from rippleb.engine.process.reaping import EXITING, KEEPER_GRACE_S, kill_keeper, reap_exiting, wait_keeper

POLL_S = 0.2
DEFAULT_MAX_BYTES = 2**30


@dataclass
class Finished:
    """How a job ended: ``kind`` is ``done`` (``value`` holds its bytes), ``raised``
    (``value`` is the one-line error), ``timeout``, ``oversized``, ``garbled`` (its control
    pipe held bytes no keeper writes; ``value``: the first of them) or ``died`` (``value``
    the worker's exit code, negative for a signal). ``method_s``: the seconds the method's
    part of the job took, measured by its keeper outside the method's process
    (:mod:`rippleb.engine.process.keeper`), None where it never started or was cut off."""

    key: object
    kind: str
    value: object
    wall_s: float
    method_s: float | None = None


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
    keeper_session: int = 0  # the keeper's PID, kept: it starts a session of that number
    result: bytearray = field(default_factory=bytearray)
    ctrl: bytearray = field(default_factory=bytearray)
    result_eof: bool = False
    ctrl_eof: bool = False
    sink: str | None = None        # the file the result goes to, past its tag (else: memory)
    sink_fd: int | None = None
    sunk: int = 0

    def size(self, name: str) -> int:
        """Bytes received on the ``result`` or ``ctrl`` pipe so far."""
        return len(self.result) + self.sunk if name == "result" else len(self.ctrl)

    @property
    def garbled(self) -> bool:
        """The control pipe holds what its keeper cannot have written: not its two lines
        (:func:`control`), or an exit code while the worker it names still runs (the keeper
        reaps its worker before it reports)."""
        parsed = control(bytes(self.ctrl))
        return parsed is None or (parsed[1] is not None and self.worker is not None)

    @property
    def worker(self) -> int | None:
        """The worker's PID as its keeper named it, once named, if it is in the keeper's
        session (so a forged PID never makes the runner kill another process)."""
        parsed = control(bytes(self.ctrl))
        if parsed is None or parsed[0] is None:
            return None
        try:
            return parsed[0] if os.getsid(parsed[0]) == self.keeper_session else None
        except OSError:
            return None

    @property
    def exit_code(self) -> int | None:
        parsed = control(bytes(self.ctrl))
        return None if parsed is None else parsed[1]

    @property
    def method_s(self) -> float | None:
        parsed = control(bytes(self.ctrl))
        return None if parsed is None or parsed[2] is None or parsed[2] < 0 else parsed[2] / 1e9


#: The keeper's two lines, ``"<worker PID> <0|1>\n"`` and ``"<exit code> <method ns>\n"``,
#: complete or cut short by a read (a prefix of them); nothing else.
_CONTROL = re.compile(rb"(?:(\d{1,10}) [01]\n(?:(-?\d{1,4}) (-1|\d{1,19})\n|-?\d{0,4}(?: -?\d{0,19})?)"
                      rb"|\d{0,10}(?: [01]?)?)")


def control(data: bytes) -> tuple[int | None, int | None, int | None] | None:
    """``(worker PID, exit code, method ns)`` from the bytes of a control pipe (None where
    not yet sent; method ns -1 where the method never started), or None when they are not
    what a keeper writes: a process of the job wrote into the pipe (docs/robustness.md).
    Parsed strictly, so no byte there can raise."""
    match = _CONTROL.fullmatch(data)
    if match is None:
        return None
    worker, code, span = match.groups()
    return (int(worker) if worker else None), (int(code) if code else None), (int(span) if span else None)


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
        A :class:`rippleb.engine.process.forkserver.ForkServer` to fork the keepers (it passes its own
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
               max_bytes: int | None = None, confine=None, sink: str | None = None) -> None:
        """Start ``fn`` (see ``context``) in an isolated worker; its stdout and stderr go to
        the file ``output`` (or /dev/null), so a chatty plugin cannot garble the CLI's output.

        ``confine``: None for rippleb's own jobs; for a method's, an :class:`~rippleb.engine.process.isolation.Confinement`
        (the directories its worker sees read-only, the files hidden from it). ``sink``: a new
        file that receives the result as it arrives, so a large one (a fitted method's state)
        never sits in this process's memory; a ``done`` job's value is then that path."""
        # Held: a keeper started but not yet tracked would be orphaned with its pipes open.
        with interrupts.held():
            reap_exiting()
            result_r, result_w = os.pipe()
            ctrl_r, ctrl_w = os.pipe()
            pid = None
            try:
                pid = self._start_keeper(fn, result_w, ctrl_w, output, confine)
            finally:  # the keeper holds the write ends now (or no keeper started)
                os.close(result_w)
                os.close(ctrl_w)
                if pid is None:  # interrupted while the server was busy: a keeper it forks
                    os.close(result_r)   # later finds these closed and ends its worker
                    os.close(ctrl_r)
            for fd in (result_r, ctrl_r):
                os.set_blocking(fd, False)
            now = time.monotonic()
            sink_fd = None if sink is None else os.open(sink, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW
                                                        | os.O_CLOEXEC, 0o600)
            self._running.append(_Running(key, pid, result_r, ctrl_r, now, now + timeout if timeout else None,
                                          max_bytes or DEFAULT_MAX_BYTES, direct=self.server is None,
                                          keeper_session=pid, sink=sink, sink_fd=sink_fd))

    def _start_keeper(self, fn, result_w: int, ctrl_w: int, output, confine) -> int:
        if self.server is not None:
            return self.server.spawn(fn, result_w, ctrl_w, self.memory_mb, output, confine)
        bound = Bound(fn, self.context)
        sys.stdout.flush()
        sys.stderr.flush()
        pid = os.fork()
        if pid == 0:
            keeper(bound, result_w, ctrl_w, self.memory_mb, output, confine)  # never returns
        return pid

    def wait(self) -> list[Finished]:
        """Block until at least one job ends (or passes its deadline); return those that did.
        Raises ``KeyboardInterrupt`` once SIGINT or SIGTERM has arrived (the jobs run on:
        :meth:`kill_all` ends them)."""
        while True:
            with interrupts.held():
                finished = self._collect()
                reap_exiting()
            if finished or not self._running:
                return finished
            interrupts.check_interrupted()
            deadlines = [r.deadline for r in self._running if r.deadline is not None]
            # Wake at least every POLL_S: a signal caught by another thread (tqdm's
            # monitor, a timer) only runs its Python handler once the main thread wakes.
            timeout = min([POLL_S] + [max(0.0, d - time.monotonic()) for d in deadlines])
            fds = [fd for r in self._running for fd, eof in ((r.result_fd, r.result_eof),
                                                             (r.ctrl_fd, r.ctrl_eof)) if not eof]
            with contextlib.suppress(InterruptedError):
                select.select(fds, [], [], timeout)

    def kill_all(self) -> None:
        """End every running job and its processes now (used on SIGINT/SIGTERM): the
        workers are killed together, so their keepers clean up side by side, then each
        keeper is awaited for a bounded time."""
        with interrupts.held():
            _kill_workers(self._running)
            while self._running:
                _end(self._running.pop())
            reap_exiting()

    def _collect(self) -> list[Finished]:
        done, now = [], time.monotonic()
        for run in list(self._running):
            _read(run)
            result = None
            if run.size("result") > run.max_bytes:
                result = Finished(run.key, "oversized", run.size("result"), now - run.started)
            elif run.garbled:
                result = Finished(run.key, "garbled", bytes(run.ctrl[:40]), now - run.started)
            elif run.exit_code is not None or run.ctrl_eof:
                _end(run, EXITING)  # the worker is gone: drain its pipe to the end
                result = _outcome(run, now)
            elif run.deadline is not None and now >= run.deadline:
                result = Finished(run.key, "timeout", None, now - run.started)
            if result is not None:
                _end(run)
                if run.sink is not None and result.kind != "done":
                    with contextlib.suppress(OSError):
                        os.unlink(run.sink)
                self._running.remove(run)
                done.append(result)
        return done


def _outcome(run: _Running, now: float) -> Finished:
    wall = now - run.started
    tag, payload = bytes(run.result[:1]), bytes(run.result[1:])
    if tag == b"D":
        return Finished(run.key, "done", payload if run.sink is None else run.sink, wall, run.method_s)
    if tag == b"R":
        return Finished(run.key, "raised", payload.decode(errors="replace"), wall, run.method_s)
    code = run.exit_code
    return Finished(run.key, "died", code, wall)


def _read(run: _Running) -> None:
    for name in ("result", "ctrl"):
        fd, buf = getattr(run, f"{name}_fd"), getattr(run, name)
        if getattr(run, f"{name}_eof"):
            continue
        while run.size(name) <= run.max_bytes:
            try:
                chunk = os.read(fd, 1 << 20)
            except BlockingIOError:
                break
            except OSError:
                chunk = b""
            if not chunk:
                setattr(run, f"{name}_eof", True)
                break
            if not buf:   # the tag stays here
                buf += chunk[:1]
                chunk = chunk[1:]
            if name == "result" and run.sink_fd is not None and buf[:1] == b"D":   # a result: to its file
                write_all(run.sink_fd, chunk)
                run.sunk += len(chunk)
            else:                                                                 # a one-line error
                buf += chunk


def _kill_workers(runs: list[_Running], wait_s: float = 1.0) -> None:
    """SIGKILL the worker of each of ``runs``; a keeper forked a moment ago may not have
    named its worker yet, so wait up to ``wait_s`` (in all) for those lines."""
    deadline = time.monotonic() + wait_s
    while True:
        for run in runs:
            _read(run)
        unknown = [r.ctrl_fd for r in runs if r.worker is None and not r.ctrl_eof]
        if not unknown or time.monotonic() >= deadline:
            break
        with contextlib.suppress(InterruptedError):
            select.select(unknown, [], [], 0.05)
    for run in runs:
        if run.exit_code is None and run.worker is not None:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.kill(run.worker, signal.SIGKILL)


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
    elif run.exit_code is None and not run.ctrl_eof:
        kill_keeper(run.keeper)  # it never named its worker: the worker dies with it (PDEATHSIG)
    if not run.direct:  # the fork server reaps it: only make sure it is gone
        if run.exit_code is None:
            _await_keeper_exit(run)
    elif cleaned:
        exiting.append((run.keeper, time.monotonic() + KEEPER_GRACE_S))
    else:
        wait_keeper(run.keeper)
    # Every writer should be gone now (the keeper ended the worker's processes before it
    # reported): take what is left in the pipes (bounded in time, in case an escaped
    # process still holds one), then close them.
    give_up = time.monotonic() + 1.0
    while not (run.result_eof and (run.ctrl_eof or cleaned)) and time.monotonic() < give_up:
        _read(run)
        if run.size("result") > run.max_bytes:
            break
        open_fds = [fd for fd, eof in ((run.result_fd, run.result_eof), (run.ctrl_fd, run.ctrl_eof or cleaned))
                    if not eof]
        if open_fds:
            with contextlib.suppress(InterruptedError):
                select.select(open_fds, [], [], 0.05)
    os.close(run.result_fd)
    os.close(run.ctrl_fd)
    if run.sink_fd is not None:
        os.close(run.sink_fd)
        run.sink_fd = None
    run.keeper = None


def _await_keeper_exit(run: _Running, grace_s: float = KEEPER_GRACE_S) -> None:
    """Wait until a keeper that is not our child has exited (its end of the control pipe
    closes); if it has not within ``grace_s``, end its whole session."""
    deadline = time.monotonic() + grace_s
    while not run.ctrl_eof and time.monotonic() < deadline:
        with contextlib.suppress(InterruptedError):
            select.select([run.ctrl_fd], [], [], 0.05)
        _read(run)
    if not run.ctrl_eof:
        kill_keeper(run.keeper)
