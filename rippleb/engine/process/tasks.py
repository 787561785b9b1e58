"""A cap on the processes and threads of one job: a ``pids`` control group of its own.

A method that forks without end (issue 41: 300 children in one row) would multiply the
memory limit, which binds each process alone. Two of the kernel's mechanisms cap it:

* the ``pids`` controller of a control group (cgroups(7); ``pids.max``): the keeper puts
  itself, before it forks the worker, in a group of its own whose limit counts the job's
  every process and thread; a fork beyond it fails with ``EAGAIN``. It needs a ``pids``
  hierarchy this process may write: root's usually, a delegated one otherwise;
* ``RLIMIT_NPROC`` (:func:`rippleb.engine.process.sandbox.lock_down`), which counts per user
  namespace, so in the worker's own it counts the job's processes alone; the kernel does
  not apply it to root (``INIT_USER``), which is where the group is there instead.

The keeper stays in its group to the end; the process that reaps it removes the group
(:func:`remove`). Where ``RLIMIT_NPROC`` binds (any user but root) no group is made at all.

Moving a process into a group through ``cgroup.procs`` takes the kernel's lock of every
thread group, whose first writer waits for an RCU grace period: 11-18 ms of wall time per
job on the cgroup v1 hierarchy of the 2-core machine (2026-11-27), during which the job's
slot runs nothing. On a v1 hierarchy the keeper writes ``0`` to ``tasks`` instead, which
moves the calling thread alone and takes no such lock (0.1 ms): a keeper just forked is one
thread, so that thread is the whole process, and whatever it forks starts in the group.
"""

from __future__ import annotations

import contextlib
import functools
import os

#: A job's group, under the group of the process that starts the run's jobs.
PREFIX = "rippleb-job-"


@functools.cache
def pids_root() -> str | None:
    """The directory of this process's group in a writable ``pids`` hierarchy (cgroup v1's
    ``pids`` controller, or cgroup v2 with ``pids`` enabled for its children), or None."""
    try:
        with open("/proc/self/mountinfo") as fh:
            mounts = [line.split() for line in fh]
        with open("/proc/self/cgroup") as fh:
            groups = [line.rstrip("\n").split(":", 2) for line in fh]
    except OSError:
        return None
    for fields in mounts:
        sep = fields.index("-")
        fstype, options, mountpoint = fields[sep + 1], fields[sep + 3].split(","), fields[4]
        if fstype == "cgroup" and "pids" in options:
            own = next((path for _, controllers, path in groups if "pids" in controllers.split(",")), None)
        elif fstype == "cgroup2":
            own = next((path for hierarchy, _, path in groups if hierarchy == "0"), None)
            if own is not None and not _enabled(os.path.join(mountpoint, own.lstrip("/")), "pids"):
                own = None
        else:
            continue
        if own is not None:
            where = os.path.join(mountpoint, own.lstrip("/"))
            if os.access(where, os.W_OK):
                return where
    return None


def _enabled(group: str, controller: str) -> bool:
    try:
        with open(os.path.join(group, "cgroup.subtree_control")) as fh:
            return controller in fh.read().split()
    except OSError:
        return False


def enter(limit: int) -> str | None:
    """Move this process into a new group that holds at most ``limit`` processes and threads,
    it included; returns the group's directory, or None where no ``pids`` hierarchy is
    writable or where ``RLIMIT_NPROC`` caps the job already (a user other than root)."""
    root = pids_root()
    if root is None or os.getuid() != 0:
        return None
    group = os.path.join(root, f"{PREFIX}{os.getpid()}")
    try:
        os.mkdir(group)
    except FileExistsError:   # a group left by a process of this PID before: emptied when it was reaped
        pass
    except OSError:
        return None
    try:
        _write(os.path.join(group, "pids.max"), str(limit))
        _join(group)
    except OSError:
        with contextlib.suppress(OSError):
            os.rmdir(group)
        return None
    return group


def _join(group: str) -> None:
    """Move this process into ``group``: through v1's ``tasks`` (this thread, no grace period:
    module docstring) when this process is one thread, else through ``cgroup.procs``."""
    tasks = os.path.join(group, "tasks")
    if os.path.exists(tasks) and len(os.listdir("/proc/self/task")) == 1:
        _write(tasks, "0")
    else:
        _write(os.path.join(group, "cgroup.procs"), str(os.getpid()))


def remove(pid: int) -> None:
    """Remove the group of the keeper ``pid``, just reaped (empty: everything in it has ended)."""
    root = pids_root()
    if root is not None:
        with contextlib.suppress(OSError):
            os.rmdir(os.path.join(root, f"{PREFIX}{pid}"))


def _write(path: str, text: str) -> None:
    with open(path, "w") as fh:
        fh.write(text)
