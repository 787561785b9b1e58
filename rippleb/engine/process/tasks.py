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
(:func:`remove`). Moving a process into a group is the costly step (an RCU grace period on a
cgroup v1 hierarchy: 14 ms measured, ``benchmarks/confine_overhead.py --steps``), so each job
moves once, and where ``RLIMIT_NPROC`` binds (any user but root) no group is made at all.
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
        _write(os.path.join(group, "cgroup.procs"), str(os.getpid()))
    except OSError:
        with contextlib.suppress(OSError):
            os.rmdir(group)
        return None
    return group


def remove(pid: int) -> None:
    """Remove the group of the keeper ``pid``, just reaped (empty: everything in it has ended)."""
    root = pids_root()
    if root is not None:
        with contextlib.suppress(OSError):
            os.rmdir(os.path.join(root, f"{PREFIX}{pid}"))


def _write(path: str, text: str) -> None:
    with open(path, "w") as fh:
        fh.write(text)
