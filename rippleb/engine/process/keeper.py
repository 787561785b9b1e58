"""The two processes of a job: the *keeper* (rippleb's code) and the *worker* it forks.

:class:`rippleb.engine.process.pool.Pool` (or the fork server, :mod:`rippleb.engine.process.forkserver`) forks a keeper
per job; the keeper takes a new session and PID namespace, becomes a child subreaper and
forks the worker, which runs the job with a memory limit, with every inherited file
descriptor closed but its result pipe, and with its output going through a pipe into a
log the keeper opened and bounds (:mod:`rippleb.engine.process.joblog`; :mod:`rippleb.engine.process.isolation`
says why each step). The keeper reports the worker's PID and,
when it has ended and everything it started is gone, its exit code and how long the
method's part of the job took, on the control pipe.

**The method's time, measured outside its process** (issue 41, item 3). The worker, in
rippleb's code before any of the method's runs (its inputs read, its walls up), writes the
clock's reading (``CLOCK_MONOTONIC``, the keeper's clock too) into a pipe of its own and
closes it; the keeper takes the job's end from the kernel (the worker's exit). Nothing the
method does can move either end: it runs after the first and cannot outlive the second
(its namespace ends with it), and its own clock and stack play no part.

The keeper never waits blindly: it watches its end of the control pipe while it waits for
the worker, and if the runner closes its end (interrupted, or gone) it ends the worker at
once. A worker blocked writing its result into a pipe nobody reads would otherwise keep
its keeper, the fork server and the runner waiting for ever (issue 25).
"""

from __future__ import annotations

import contextlib
import errno
import gc
import os
import resource
import select
import shutil
import signal
import sys
import tempfile
import time
import traceback

from rippleb import integrity
from rippleb.engine.process import isolation, sandbox, scrub, tasks
from rippleb.engine.process.joblog import JobLog
from rippleb.registry import one_line


def keeper(fn, result_w: int, ctrl_w: int, memory_mb, output, confine=None) -> None:
    """rippleb's own process between the runner and a job: session, namespaces, cleanup.
    Runs ``fn()`` in a worker it forks; never returns.

    ``confine`` is None for rippleb's own jobs (simulations), else what a method's worker
    must not touch (:class:`rippleb.engine.process.isolation.Confinement`); such a worker gets a
    scratch directory of its own, the one place it may write, removed when it ends."""
    try:
        # First: Ctrl-C reaches the runner's whole process group, and what is inherited
        # from the runner until here is its handler (the runner decides what a signal ends).
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        isolation.name_process("rippleb-keeper")
        _keep_inherited_pages_shared()
        os.setsid()
        isolation.close_fds_except(result_w, ctrl_w)
        isolation.not_dumpable()   # its descriptors (the control pipe) out of the worker's reach
        log = JobLog(output)
        log.open()   # before the worker can change what the run directory's paths lead to
        confine = None if confine is None else _as_confinement(confine)
        # Before the namespaces: a group of the host's pids hierarchy caps the job's processes
        # (its worker's and their descendants', this keeper's one among them).
        group = tasks.enter(sandbox.MAX_TASKS + 1) if confine is not None else None
        granted = isolation.new_namespaces()
        scratch, made = _scratch(confine, granted.mount)
        isolation.become_subreaper()
        go_r, go_w = os.pipe()   # the worker starts once the keeper has named it (below)
        clock = Clock()
        worker = os.fork()
        if worker == 0:
            # Its own process group: a worker that signals "its" group (killpg(0, ...), or
            # kill(0, ...), which is what kill(getppid()) becomes inside a PID namespace)
            # must not reach the keeper, whose death would lose the row it reports.
            os.setpgid(0, 0)
            os.close(ctrl_w)
            os.close(go_w)
            os.close(clock.read_fd)
            log.give_to_worker()
            os.read(go_r, 1)   # a job that writes into the control pipe must not get there first
            os.close(go_r)
            _worker(fn, result_w, memory_mb, confine, scratch, granted._replace(capped=group is not None),
                    clock.write_fd)  # never returns
        os.close(result_w)
        os.close(log.write_fd)
        os.close(clock.write_fd)
        _write_all(ctrl_w, f"{worker} {int(granted.pid)}\n".encode())
        os.close(go_r)
        os.close(go_w)   # the worker's read returns: it may start
        status = _wait_worker(worker, ctrl_w, log, clock)
        if granted.pid:  # the kernel ended the namespace with its first process: nothing left to hunt
            isolation.reap_exited()
        else:
            isolation.end_descendants()
        log.close()   # the log is whole before the runner hears the job ended
        if made:
            _remove(scratch)
        _write_all(ctrl_w, f"{os.waitstatus_to_exitcode(status)} {clock.span_ns()}\n".encode())
    finally:
        os._exit(0)


class Clock:
    """The keeper's measure of the method's part of a job (module docstring): a pipe the
    worker writes its start into once, and the worker's end as the keeper saw it."""

    def __init__(self):
        self.read_fd, self.write_fd = os.pipe()
        os.set_blocking(self.read_fd, False)
        self.start = b""
        self.end: int | None = None

    def read(self) -> bool:
        """Take what the pipe holds; False once the worker has closed it."""
        try:
            chunk = os.read(self.read_fd, 8 - len(self.start)) if len(self.start) < 8 else b""
        except BlockingIOError:
            return True
        except OSError:
            return False
        self.start += chunk
        return bool(chunk) and len(self.start) < 8

    def span_ns(self) -> int:
        """Nanoseconds from the method's start to the worker's end; -1 if it never started."""
        if len(self.start) < 8 or self.end is None:
            return -1
        return max(0, self.end - int.from_bytes(self.start, "little"))


def start_method(write_fd: int) -> None:
    """In the worker, in rippleb's code, as the method's part begins: the clock's reading to
    the keeper, then the pipe closed (the method never holds it)."""
    _write_all(write_fd, time.monotonic_ns().to_bytes(8, "little"))
    os.close(write_fd)


def _wait_worker(worker: int, ctrl_w: int, log: JobLog, clock: Clock) -> int:
    """Wait for ``worker`` to end and return its wait status, copying its output into
    ``log`` meanwhile; end it at once if the runner closes its end of the control pipe
    (``POLLERR`` on ours), i.e. no one will read what the worker sends, nor wait for it.

    Where the kernel has no process file descriptors (``pidfd_open``, Linux 5.3) the
    output is copied until the worker closes it, then the worker is waited for plainly:
    the runner and the fork server still end the keeper themselves.
    """
    try:
        pidfd = os.pidfd_open(worker)
    except (AttributeError, OSError):
        while log.drain():
            select.select([log.read_fd], [], [])
        status = os.waitpid(worker, 0)[1]
        clock.end = time.monotonic_ns()
        clock.read()
        return status
    watch = select.poll()
    watch.register(pidfd, select.POLLIN)
    watch.register(ctrl_w, 0)  # only errors: POLLERR once the reading end is closed
    watch.register(log.read_fd, select.POLLIN)
    watch.register(clock.read_fd, select.POLLIN)
    try:
        while True:
            pid, status = os.waitpid(worker, os.WNOHANG)
            if pid:
                clock.end = time.monotonic_ns()
                clock.read()
                return status
            ready = {fd for fd, _ in watch.poll()}
            if log.read_fd in ready and not log.drain():
                watch.unregister(log.read_fd)   # every writer closed it: no more to copy
            if clock.read_fd in ready and not clock.read():
                watch.unregister(clock.read_fd)
            if ctrl_w in ready:
                watch.unregister(ctrl_w)
                with contextlib.suppress(ProcessLookupError):
                    os.kill(worker, signal.SIGKILL)
    finally:
        os.close(pidfd)


def _worker(fn, result_w: int, memory_mb, confine, scratch, granted, clock_w: int) -> None:
    try:
        isolation.name_process("rippleb-worker")
        _keep_inherited_pages_shared()
        isolation.die_with_parent()
        isolation.close_fds_except(result_w, clock_w)
        _rebind_output()
        _limit_memory(memory_mb)   # first: whatever the job holds counts, its inputs included
        try:
            # A method's job in two parts (rippleb.engine.jobs.Job.prepare): rippleb's code
            # reads and verifies its inputs, then the walls go up, then the method's code runs.
            prepare = getattr(fn, "prepare", None) if confine is not None else None
            phase = prepare() if prepare is not None else fn
            if confine is not None:
                _confine(confine, scratch, granted)
            start_method(clock_w)
            tag, payload = b"D", phase()
        except BaseException as exc:  # everything a plugin can raise becomes a row status
            traceback.print_exc()
            tag, payload = b"R", one_line(exc).encode()
        # A tag, then the payload as the job made it (bytes, or a sequence of them): never
        # joined here, so a large result (a fitted state) is not copied once more.
        for chunk in (tag, *(payload if isinstance(payload, (list, tuple)) else (payload,))):
            _write_all(result_w, chunk)
        os.close(result_w)
        sys.stdout.flush()
        sys.stderr.flush()
    finally:
        # Skip the parent's atexit handlers and buffered files (pytest, tqdm) in the child.
        os._exit(0)


class Bound:
    """A job with what it is called with (``job(context)``, or ``job()`` when ``context`` is
    None), as a keeper runs it: whole (``bound()``), or, for a method's worker, in the two
    parts of :meth:`prepare`.

    Parameters
    ----------
    job
        The job; one with a ``prepare(context)`` method (:class:`rippleb.engine.jobs.Job`)
        returns from it the part that runs the method's code.
    context
        What the job is called with (the registry), or None.
    always
        Call the job with ``context`` even when it is None (the fork server passes its own,
        whatever it is); else None means a job without arguments.
    """

    def __init__(self, job, context=None, always: bool = False):
        self.job = job
        self.args = (context,) if always or context is not None else ()

    def __call__(self):
        return self.job(*self.args)

    def prepare(self):
        """rippleb's part of the job, run before the walls; returns the method's part. A job
        without a ``prepare`` runs whole behind the walls."""
        prepare = getattr(self.job, "prepare", None)
        return self if prepare is None else prepare(*self.args)


def _scratch(confine, own_mounts: bool) -> tuple[str | None, bool]:
    """The directory a method's worker may write, and whether this keeper made it.

    With a mount namespace of its own, the worker mounts a private tmpfs over the run's
    scratch directory (:func:`rippleb.engine.process.isolation.confine_files`), which vanishes with
    it: nothing to make or remove. Otherwise the keeper makes one (making and removing a
    directory per job cost about 1 ms, ``shutil.rmtree`` alone 3 ms in a forked process).
    """
    if confine is None:
        return None, False
    if own_mounts and confine.scratch_in is not None:
        return confine.scratch_in, False
    return tempfile.mkdtemp(prefix="rippleb-scratch-", dir=confine.scratch_in), True


def _remove(scratch: str) -> None:
    try:
        os.rmdir(scratch)   # most jobs leave it empty
    except OSError:
        shutil.rmtree(scratch, ignore_errors=True)


def _as_confinement(confine) -> isolation.Confinement:
    """``confine`` as a :class:`~rippleb.engine.process.isolation.Confinement` (a bare sequence:
    the read-only directories)."""
    return confine if isinstance(confine, isolation.Confinement) else isolation.Confinement(tuple(confine))


def _confine(confine: isolation.Confinement, scratch: str, granted: isolation.Namespaces) -> None:
    """In a method's worker, before its code runs: close what the kernel lets it close off
    (docs/robustness.md), mounts first (:mod:`rippleb.engine.process.isolation`), then the walls
    that keep them (:mod:`rippleb.engine.process.sandbox`); say on its own log what it could not,
    so a reader of the row's log knows the run was open. Its command line and environment
    (the runner's) are wiped (:mod:`rippleb.engine.process.scrub`), and its temporary files go
    to ``scratch``."""
    hidden = [integrity.key_path(), *confine.hidden]
    mounts = (isolation.confine_files(confine.read_only, hidden_files=hidden, scratch=confine.scratch_in)
              if granted.mount else ["a mount namespace"])
    network = [] if granted.net else ["a network namespace (the network closed)"]
    scrub.wipe_command_line()
    scrub.scrub_environment()
    os.environ["TMPDIR"] = scratch
    tempfile.tempdir = None
    _numba_cache_into(scratch)
    missing = mounts + network + sandbox.lock_down(
        scratch, nested_namespace=granted.mount and not mounts, readable=confine.readable,
        own_proc=granted.mount and "a /proc of its own" not in mounts, own_users=granted.pid, capped=granted.capped)
    if missing:
        print(f"rippleb: this worker is not confined: no {', no '.join(missing)} (the kernel refused)",
              file=sys.stderr)
    else:
        # Its own /proc, in its own PID namespace: no other process can name it, so it may
        # be dumpable again, as a plain process is (a method that reads /proc/self/mem, /environ
        # or /io as an unprivileged user; those files belong to root in a process that is not).
        isolation.dumpable_again()


def _numba_cache_into(scratch: str) -> None:
    """numba keeps compiled functions beside their source or in ``$HOME``, both read-only to
    a method's worker now, and a function with ``cache=True`` then fails as it is defined
    ("no locator available"), e.g. rippleb.dsp imported by a plugin in ``rippleb list``'s
    probe. Its cache goes to the scratch directory instead: a plugin's kernels compile in
    each job (the fork server's built-in ones are compiled already). numba reads
    ``NUMBA_CACHE_DIR`` when imported, and ``config.CACHE_DIR`` when a function is defined."""
    os.environ["NUMBA_CACHE_DIR"] = scratch
    config = sys.modules.get("numba.core.config")
    if config is not None:
        config.CACHE_DIR = scratch


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


def _rebind_output() -> None:
    """Point Python's stdout and stderr at fds 1 and 2 (the job's output pipe, :mod:`rippleb.engine.process.joblog`)."""
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
