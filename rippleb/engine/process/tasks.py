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

The keeper leaves its group and removes it once the job's processes are gone (a keeper
killed before that leaves an empty group, removed by the next keeper of this process).
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
    writable (then only ``RLIMIT_NPROC`` caps the job)."""
    root = pids_root()
    if root is None:
        return None
    _remove_stale(root)
    group = os.path.join(root, f"{PREFIX}{os.getpid()}")
    try:
        os.mkdir(group)
    except FileExistsError:
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


def leave(group: str | None) -> None:
    """Move this process back to the group it came from and remove the job's group (empty
    once the job's processes are gone)."""
    if group is None:
        return
    with contextlib.suppress(OSError):
        _write(os.path.join(os.path.dirname(group), "cgroup.procs"), str(os.getpid()))
        os.rmdir(group)


def _remove_stale(root: str) -> None:
    """Remove the empty groups of keepers that were killed before they could."""
    with contextlib.suppress(OSError):
        for name in os.listdir(root):
            if name.startswith(PREFIX) and not _alive(name[len(PREFIX):]):
                with contextlib.suppress(OSError):
                    os.rmdir(os.path.join(root, name))


def _alive(pid: str) -> bool:
    try:
        os.kill(int(pid), 0)
    except (ValueError, ProcessLookupError):
        return False
    except PermissionError:
        return True
    return True


def _write(path: str, text: str) -> None:
    with open(path, "w") as fh:
        fh.write(text)
