"""Process control for code rippleb does not trust: a method's import, fit and steps.

A job runs in two processes (:mod:`rippleb.engine.process.pool`): a *keeper*, rippleb's own code, and
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
from dataclasses import dataclass
from typing import NamedTuple

CLONE_NEWNS = 0x00020000
CLONE_NEWUSER = 0x10000000
CLONE_NEWPID = 0x20000000
CLONE_NEWNET = 0x40000000
PR_SET_CHILD_SUBREAPER = 36
PR_SET_PDEATHSIG = 1
PR_SET_NAME = 15
PR_GET_DUMPABLE, PR_SET_DUMPABLE = 3, 4
# mount(2) flags
MS_RDONLY, MS_NOSUID, MS_NODEV, MS_NOEXEC = 1, 2, 4, 8
MS_REMOUNT, MS_NOATIME, MS_NODIRATIME, MS_BIND, MS_REC, MS_PRIVATE = 32, 1024, 2048, 4096, 16384, 1 << 18
MS_RELATIME = 1 << 21
#: Where the terminals are: hidden from a method, which could otherwise write to rippleb's
#: own terminal by opening its pseudo-terminal device (same user, same permissions).
TERMINALS = "/dev/pts"
#: Where the system's services keep their sockets (D-Bus, a container engine's): hidden from a
#: method. A named socket is reached by connect(2), which neither Landlock's read rules nor a
#: network namespace of its own govern; a mount over the directory does.
SOCKETS = "/run"
#: A method's scratch directory: a tmpfs of its own, at most 1 GiB (its pages are memory
#: that ``--memory-limit``'s address-space cap does not count).
SCRATCH_OPTIONS = "size=1g,mode=0700"


@functools.cache
def libc():
    # Loaded once, in the runner: a forked keeper and worker inherit it instead of each
    # loading it again (a measurable share of a short job's start).
    return ctypes.CDLL(None, use_errno=True)


with contextlib.suppress(OSError, TypeError):  # not a POSIX C library: the calls below say so
    libc()


def become_subreaper() -> bool:
    """Make orphaned descendants re-parent to this process; False where unsupported."""
    try:
        return libc().prctl(PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def name_process(name: str) -> None:
    """Name this process as ``ps``, ``top`` and ``perf`` show it (``/proc/self/comm``, at most
    15 bytes): the fork server, a keeper and a worker are otherwise all ``python``, and
    where a run's time goes is read per kind of process (docs/robustness.md, "The fork
    itself"). Nothing else reads it."""
    with contextlib.suppress(OSError, AttributeError, TypeError):
        libc().prctl(PR_SET_NAME, ctypes.c_char_p(name.encode()[:15]), 0, 0, 0)


def die_with_parent() -> None:
    """Ask the kernel to SIGKILL this process when its parent (the keeper) dies."""
    with contextlib.suppress(OSError, AttributeError):
        libc().prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)


class Namespaces(NamedTuple):
    """Which new namespaces a job's processes got: ``pid`` (with a user namespace),
    ``mount`` and ``net`` (a network namespace with nothing in it but a loopback that is down);
    ``capped``: whether a control group caps its processes (:mod:`rippleb.engine.process.tasks`)."""

    pid: bool
    mount: bool
    net: bool
    capped: bool = False


#: What :func:`new_namespaces` asks for, best first: ``(unshare flags, what they grant)``.
NAMESPACE_CHOICES = ((CLONE_NEWUSER | CLONE_NEWPID | CLONE_NEWNS | CLONE_NEWNET, Namespaces(True, True, True)),
                     (CLONE_NEWUSER | CLONE_NEWPID | CLONE_NEWNS, Namespaces(True, True, False)),
                     (CLONE_NEWUSER | CLONE_NEWPID | CLONE_NEWNET, Namespaces(True, False, True)),
                     (CLONE_NEWUSER | CLONE_NEWPID, Namespaces(True, False, False)))
NONE = Namespaces(False, False, False)


def new_namespaces() -> Namespaces:
    """Put this process's *future* children in a new user and PID namespace, and this
    process in a new mount and network namespace (which of them the kernel granted).

    Must be called in a single-threaded process (a freshly forked keeper). The user
    namespace maps the caller's uid and gid onto themselves, so files keep their owner.
    The mount namespace lets the worker mount a /proc of its own and cover the run
    directory (:func:`confine_files`) without touching anyone else's view of the files.
    The network namespace holds no interface but its own loopback, down: no address of
    this host or any other, and no abstract Unix socket outside it, can be reached (a
    Dask scheduler on 127.0.0.1 among them). Where the kernel or its policy refuses, less
    is done, and nothing where it refuses all.
    """
    ids = os.getuid(), os.getgid()   # read before: inside an unmapped namespace they are 65534
    for flags, granted in NAMESPACE_CHOICES:
        try:
            if libc().unshare(flags) == 0:
                map_ids(*ids)
                return granted
        except (OSError, AttributeError):
            break
    return NONE


def map_ids(uid: int, gid: int) -> None:
    """Map this process's user and group ids onto themselves in its new user namespace.

    A process that is not dumpable has its ``/proc/self`` files owned by root, which an
    unprivileged user's new namespace cannot write; so it is dumpable for these writes
    (as an unprivileged user the ids stayed unmapped, and a second, nested namespace,
    which needs mapped ids, was refused: issue 34). Nothing can name it meanwhile: its
    jobs run in PID namespaces of their own."""
    was = libc().prctl(PR_GET_DUMPABLE, 0, 0, 0, 0)
    if was == 0:
        dumpable_again()
    try:
        _write("/proc/self/setgroups", "deny")
        _write("/proc/self/uid_map", f"{uid} {uid} 1")
        _write("/proc/self/gid_map", f"{gid} {gid} 1")
    except OSError:
        pass  # unmapped ids still work for file access under the caller's credentials
    finally:
        if was == 0:
            not_dumpable()


@contextlib.contextmanager
def undumpable():
    """This process not dumpable (:func:`not_dumpable`) within the block, as before after it:
    a run's jobs, of the same user, can then not open the runner's descriptors (its
    terminal, its results) nor read its memory (the truths, a sealed run's salt)."""
    try:
        was = libc().prctl(PR_GET_DUMPABLE, 0, 0, 0, 0)
    except (OSError, AttributeError):
        was = -1
    not_dumpable()
    try:
        yield
    finally:
        if was > 0:
            with contextlib.suppress(OSError, AttributeError):
                libc().prctl(PR_SET_DUMPABLE, was, 0, 0, 0)


def dumpable_again() -> None:
    """Undo :func:`not_dumpable` in this process (a confined worker, seen by no one)."""
    with contextlib.suppress(OSError, AttributeError):
        libc().prctl(PR_SET_DUMPABLE, 1, 0, 0, 0)


def not_dumpable() -> None:
    """Make this process (and what it forks) not dumpable: a process of the same user
    without ``CAP_SYS_PTRACE`` over it can then neither read its memory nor open its file
    descriptors through ``/proc/<pid>/fd`` (the keeper's control pipe, the runner's
    terminal and results). A method's worker never holds that capability over its
    keeper: its user namespace is the keeper's child."""
    with contextlib.suppress(OSError, AttributeError):
        libc().prctl(PR_SET_DUMPABLE, 0, 0, 0, 0)


@dataclass(frozen=True)
class Confinement:
    """What a method's worker must not touch.

    Parameters
    ----------
    read_only
        Directories it sees read-only beyond what Landlock denies (the run directory, the
        cache): a mount holds even where Landlock is missing.
    hidden
        Files covered by ``/dev/null`` (rippleb's key, a sealed run's salt file).
    scratch_in
        The directory that holds the job's scratch directory (None: the system's
        temporary directory).
    readable
        What the method may read beyond the libraries (its own package: a directory or
        a module file; :mod:`rippleb.engine.process.landlock`).
    """

    read_only: tuple[str, ...] = ()
    hidden: tuple[str, ...] = ()
    scratch_in: str | None = None
    readable: tuple[str, ...] = ()

    @classmethod
    def of(cls, read_only, hidden, scratch_in, readable=()) -> "Confinement":
        """From paths (None where there is none), as strings: it is pickled to the fork server."""
        return cls(tuple(str(p) for p in read_only if p), tuple(str(p) for p in hidden if p),
                   str(scratch_in) if scratch_in else None, tuple(str(p) for p in readable if p))


def confine_files(read_only, hidden_files=(), scratch=None) -> list[str]:
    """In a worker that is PID 1 of its own PID and mount namespaces: a /proc of its own
    namespace (the host's processes, its keeper's and the runner's descriptors out of
    sight), the terminals and the services' sockets hidden (:data:`TERMINALS`, :data:`SOCKETS`), each existing directory of
    ``read_only`` (the run directory, the cache) mounted read-only over itself, each
    existing file of ``hidden_files`` (rippleb's key) covered by ``/dev/null``, and a
    private tmpfs over ``scratch`` (:data:`SCRATCH_OPTIONS`), gone with the worker.

    Only this worker's view changes: its mount namespace is private (``MS_PRIVATE``), so
    nothing propagates back. Files it had opened before keep their access (its output
    log). Returns what could not be done, one phrase each (empty when all held).
    """
    missing = []
    if _mount(None, "/", None, MS_REC | MS_PRIVATE) != 0:
        return ["a private mount namespace"]
    if _mount("proc", "/proc", "proc", MS_NOSUID | MS_NODEV | MS_NOEXEC) != 0:
        missing.append("a /proc of its own")
    inside = scratch is not None and os.path.realpath(scratch).startswith(SOCKETS + "/")
    for covered in (TERMINALS,) + (() if inside else (SOCKETS,)):   # a scratch directory under /run stays reachable
        if os.path.isdir(covered) and _mount("tmpfs", covered, "tmpfs", MS_NOSUID | MS_NODEV | MS_NOEXEC,
                                             "size=4k,mode=0555") != 0:
            missing.append(f"{covered} hidden")
    for path in dict.fromkeys(str(p) for p in read_only):
        if os.path.isdir(path) and not _read_only(path):
            missing.append(f"{path} read-only")
    for path in map(str, hidden_files):
        if os.path.isfile(path) and _mount(os.devnull, path, None, MS_BIND) != 0:
            missing.append(f"{path} hidden")
    if scratch is not None and _mount("tmpfs", scratch, "tmpfs", MS_NOSUID | MS_NODEV, SCRATCH_OPTIONS) != 0:
        missing.append("a scratch directory of its own")
    return missing


def _read_only(path: str) -> bool:
    """Bind ``path`` over itself and make that mount read-only, keeping the flags the
    kernel locks in a user namespace (nosuid, nodev, noexec, atime) as they were."""
    if _mount(path, path, None, MS_BIND | MS_REC) != 0:
        return False
    kept = os.statvfs(path).f_flag & (MS_NOSUID | MS_NODEV | MS_NOEXEC | MS_NOATIME | MS_NODIRATIME | MS_RELATIME)
    return _mount(None, path, None, MS_REMOUNT | MS_BIND | MS_RDONLY | kept) == 0


def _mount(source, target, fstype, flags: int, data: str | None = None) -> int:
    def arg(text):
        return None if text is None else os.fsencode(text)
    try:
        return libc().mount(arg(source), arg(target), arg(fstype), flags, arg(data))
    except (OSError, AttributeError, ctypes.ArgumentError):
        return -1


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
