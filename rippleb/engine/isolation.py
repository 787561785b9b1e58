"""Process control for code rippleb does not trust: a method's import, fit and steps.

A job runs in two processes (:mod:`rippleb.engine.pool`): a *keeper*, rippleb's own code, and
the *worker* it forks, which runs the job. The keeper

* starts a new session (``setsid``), and puts the worker in a process group of its own,
  so a worker that signals "its" process group reaches only itself and its own children,
  never the runner nor the keeper that reports how it ended;
* moves the worker into a new PID namespace (``unshare(CLONE_NEWUSER | CLONE_NEWPID)``,
  allowed to unprivileged users on most Linux systems). The worker is then PID 1 of its
  namespace: it cannot name the runner's PID to signal it, and when it ends the kernel
  ends every process it left behind, however deeply forked or re-sessioned;
* is a *child subreaper* (``prctl(PR_SET_CHILD_SUBREAPER)``): where namespaces are not
  permitted, orphans of the worker are re-parented to the keeper, which kills and reaps
  every descendant once the worker has ended (:func:`end_descendants`).

Without a PID namespace, a worker can still signal the runner by its PID (any process of
the same user can); that limit is documented in ``docs/robustness.md``.
"""

from __future__ import annotations

import contextlib
import ctypes
import functools
import os
import select
import signal
import time

CLONE_NEWUSER = 0x10000000
CLONE_NEWPID = 0x20000000
PR_SET_CHILD_SUBREAPER = 36
PR_SET_PDEATHSIG = 1


@functools.cache
def _libc():
    # Loaded once, in the runner: a forked keeper and worker inherit it instead of each
    # loading it again (a measurable share of a short job's start).
    return ctypes.CDLL(None, use_errno=True)


with contextlib.suppress(OSError, TypeError):  # not a POSIX C library: the calls below say so
    _libc()


def become_subreaper() -> bool:
    """Make orphaned descendants re-parent to this process; False where unsupported."""
    try:
        return _libc().prctl(PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def die_with_parent() -> None:
    """Ask the kernel to SIGKILL this process when its parent (the keeper) dies."""
    with contextlib.suppress(OSError, AttributeError):
        _libc().prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)


def new_pid_namespace() -> bool:
    """Put this process's *future* children in a new user and PID namespace.

    Must be called in a single-threaded process (a freshly forked keeper). The user
    namespace maps the caller's uid and gid onto themselves, so files keep their owner.
    Returns False (and changes nothing) where the kernel or its policy refuses.
    """
    uid, gid = os.getuid(), os.getgid()
    try:
        if _libc().unshare(CLONE_NEWUSER | CLONE_NEWPID) != 0:
            return False
    except (OSError, AttributeError):
        return False
    try:
        _write("/proc/self/setgroups", "deny")
        _write("/proc/self/uid_map", f"{uid} {uid} 1")
        _write("/proc/self/gid_map", f"{gid} {gid} 1")
    except OSError:
        pass  # unmapped ids still work for file access under the caller's credentials
    return True


def _write(path: str, text: str) -> None:
    with open(path, "w") as fh:
        fh.write(text)


def children_of(pid: int) -> list[int]:
    """PIDs whose parent is ``pid`` (scanned from /proc)."""
    found = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat", "rb") as fh:
                stat = fh.read()
        except OSError:
            continue
        # The command name may hold spaces and parentheses: parse after the last ')'.
        fields = stat[stat.rfind(b")") + 2:].split()
        if len(fields) > 1 and int(fields[1]) == pid:
            found.append(int(entry))
    return found


def end_descendants(rounds: int = 50) -> None:
    """SIGKILL and reap every descendant of this (subreaper) process.

    Killing a child re-parents its own children to us, hence the rounds.
    """
    me = os.getpid()
    for _ in range(rounds):
        kids = children_of(me)
        if not kids:
            break
        for pid in kids:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.kill(pid, signal.SIGKILL)
        for pid in kids:  # SIGKILL cannot be caught: each wait returns promptly
            with contextlib.suppress(ChildProcessError):
                os.waitpid(pid, 0)
    reap_exited()


def reap_exited() -> list[int]:
    """Collect every child that has already exited, without blocking; return their PIDs."""
    reaped = []
    while True:
        try:
            pid, _ = os.waitpid(-1, os.WNOHANG)
        except ChildProcessError:
            return reaped
        if pid == 0:
            return reaped
        reaped.append(pid)


def wait_exit(pid: int, timeout: float) -> bool:
    """Reap the child ``pid`` if it exits within ``timeout`` seconds; False if it is still
    running then. True also if it was reaped already."""
    deadline = time.monotonic() + timeout
    try:
        fd = os.pidfd_open(pid)
    except (AttributeError, OSError):  # no process file descriptors: poll
        fd = None
    try:
        while True:
            try:
                if os.waitpid(pid, os.WNOHANG)[0]:
                    return True
            except ChildProcessError:
                return True
            left = deadline - time.monotonic()
            if left <= 0:
                return False
            if fd is None:
                time.sleep(min(left, 0.01))
            else:
                select.select([fd], [], [], left)
    finally:
        if fd is not None:
            os.close(fd)


def close_fds_except(*keep: int) -> None:
    """Close every inherited file descriptor above 2 but ``keep``: a worker must not
    reach the runner's files (the run directory, the results, other jobs' pipes)."""
    keep_set = sorted({fd for fd in keep if fd > 2})
    low = 3
    for fd in keep_set:
        os.closerange(low, fd)
        low = fd + 1
    os.closerange(low, _max_fd())


def _max_fd() -> int:
    try:
        return max(int(name) for name in os.listdir("/proc/self/fd")) + 1
    except (OSError, ValueError):
        return os.sysconf("SC_OPEN_MAX")
