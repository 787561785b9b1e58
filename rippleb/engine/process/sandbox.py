"""The walls a method's worker cannot take down (issue 34): applied in the forked worker,
after :func:`rippleb.engine.process.isolation.confine_files` and before any plugin code runs.

The mounts of :mod:`rippleb.engine.process.isolation` alone did not hold: the worker owned the user
namespace they were made in, so it held every capability over them and unmounted the
key's cover, the read-only run directory and its ``/proc``. Each step below is the
kernel's own mechanism, and none can be undone by the process it is applied to:

1. **A second user namespace** (``unshare(CLONE_NEWUSER)``): whatever capabilities the
   worker holds from then on are those of a user namespace that does not own its mount
   namespace, and mounting, unmounting or remounting needs ``CAP_SYS_ADMIN`` in the owner
   (user_namespaces(7), mount_namespaces(7)). A new mount namespace as well
   (``CLONE_NEWNS``, which would lock the copied mounts) cost a second mount tree to build
   and tear down per job, about 2 ms on a loaded machine, for nothing more.
2. **No new privileges** (``PR_SET_NO_NEW_PRIVS``): no set-uid program gives any back;
   required for the two steps after it.
3. **Landlock** (landlock(7), :mod:`rippleb.engine.process.landlock`): reading only the
   libraries and the method's own package, writing only beneath the job's scratch directory
   (a tmpfs of its own, :data:`rippleb.engine.process.isolation.SCRATCH_OPTIONS`); no TCP
   connection, no abstract Unix socket or signal outside its own processes.
4. **seccomp** through libseccomp (the library behind Docker's, systemd's and Flatpak's
   filters): :data:`DENIED_CALLS` fail with ``EPERM``, a ``clone`` that asks for a new
   namespace too, and ``clone3`` (whose flags a filter cannot read) with ``ENOSYS``, which
   makes the C library fall back to ``clone``.
5. **No capabilities**: the bounding and ambient sets are emptied, then the effective,
   permitted and inheritable sets.
6. **A process cap** (``RLIMIT_NPROC`` at :data:`MAX_TASKS`, soft and hard): counted per
   user namespace, so in the worker's own one it counts the job's processes and threads
   alone, and without ``CAP_SYS_RESOURCE`` in the host's namespace it cannot be raised.

Nothing here execs: the fork server's preloaded worker keeps its imports. Where the kernel
grants less (no user namespaces, no Landlock, no libseccomp), the steps it grants are
still taken and :func:`lock_down` names the rest; :func:`missing_protections` asks at the
start of each run, so the run can say what it lacks and ``--sealed`` can refuse.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import errno
import functools
import os
import resource
import warnings

from rippleb.engine.process import isolation, landlock, tasks
from rippleb.errors import InputError, RunWarning

#: Calls no method needs that would let it reach past its walls: mounts (old and new API),
#: tracing other processes or reading their memory, new or other namespaces, kernel BPF
#: programs, the kernel keyrings, performance counters.
DENIED_CALLS = ("mount", "umount2", "pivot_root", "move_mount", "open_tree", "fsopen", "fsmount", "fsconfig",
                "fspick", "mount_setattr", "ptrace", "process_vm_readv", "process_vm_writev", "unshare",
                "setns", "bpf", "keyctl", "add_key", "request_key", "perf_event_open")
#: Processes and threads one job may hold at once (its worker included): a fork bomb stops
#: there (issue 41: 300 children in one row), each of them bounded by the memory limit.
#: A built-in method's job runs one; OpenBLAS is held at one thread (rippleb.numerics), and
#: a method's own pool of threads or processes has room up to this.
MAX_TASKS = 64
#: ``clone`` flags that ask for a new namespace (sched.h).
NAMESPACE_FLAGS = (0x00020000, 0x02000000, 0x04000000, 0x08000000, 0x10000000, 0x20000000, 0x40000000)

PR_SET_NO_NEW_PRIVS, PR_CAPBSET_DROP, PR_CAP_AMBIENT, PR_CAP_AMBIENT_CLEAR_ALL = 38, 24, 47, 4
PR_SET_SECCOMP, SECCOMP_MODE_FILTER = 22, 2
SYS_CAPSET = 126   # x86-64
SCMP_ACT_ALLOW = 0x7FFF0000
SCMP_CMP_MASKED_EQ = 7


def SCMP_ACT_ERRNO(code: int) -> int:   # noqa: N802 - libseccomp's name
    return 0x00050000 | (code & 0xFFFF)


class _ArgCmp(ctypes.Structure):
    _fields_ = [("arg", ctypes.c_uint), ("op", ctypes.c_int), ("datum_a", ctypes.c_uint64),
                ("datum_b", ctypes.c_uint64)]


@functools.cache
def _seccomp():
    """libseccomp, loaded once in the runner (a worker inherits it), or None if absent."""
    name = ctypes.util.find_library("seccomp") or "libseccomp.so.2"
    try:
        lib = ctypes.CDLL(name, use_errno=True)
    except OSError:
        return None
    lib.seccomp_init.restype = ctypes.c_void_p
    lib.seccomp_init.argtypes = [ctypes.c_uint32]
    lib.seccomp_rule_add_array.argtypes = [ctypes.c_void_p, ctypes.c_uint32, ctypes.c_int, ctypes.c_uint,
                                           ctypes.POINTER(_ArgCmp)]
    lib.seccomp_syscall_resolve_name.argtypes = [ctypes.c_char_p]
    lib.seccomp_export_bpf.argtypes = [ctypes.c_void_p, ctypes.c_int]
    lib.seccomp_release.argtypes = [ctypes.c_void_p]
    return lib


def _syscall(*args) -> int:
    libc = isolation.libc()
    libc.syscall.restype = ctypes.c_long
    return libc.syscall(*args)


def lock_down(scratch: str | None, nested_namespace: bool, readable=(), own_proc: bool = True,
              own_users: bool = True, capped: bool = False) -> list[str]:
    """Apply every step this kernel grants (module docstring) to this process; return what
    it could not, one phrase each (empty when all held). ``scratch``: the one directory
    this process may write; ``nested_namespace``: keep its mounts out of its reach (only
    where it runs in a user namespace of rippleb's, with mounts to keep); ``readable``
    and ``own_proc``: what it may read beyond the libraries (:func:`rippleb.engine.process.landlock.restrict`);
    ``own_users``: it runs in a user namespace of its own, where the process cap counts
    its own processes only (elsewhere it would count every process of the user);
    ``capped``: a control group caps them already (:mod:`rippleb.engine.process.tasks`)."""
    capped = (own_users and _limit_tasks()) or capped
    missing = [] if capped else ["a cap on its processes"]
    if nested_namespace and not _second_user_namespace():
        missing.append("a second user namespace (mounts it cannot undo)")
    if _prctl(PR_SET_NO_NEW_PRIVS, 1) != 0:
        missing.append("no-new-privileges")
    missing += landlock.restrict(scratch, readable, own_proc)
    if not _seccomp_filter():
        missing.append("a seccomp filter (libseccomp)")
    if not _drop_capabilities():
        missing.append("an empty capability set")
    return missing


def _limit_tasks() -> bool:
    """``RLIMIT_NPROC`` at :data:`MAX_TASKS`; False where the kernel does not apply it (root)."""
    try:
        resource.setrlimit(resource.RLIMIT_NPROC, (MAX_TASKS, MAX_TASKS))
    except (OSError, ValueError):
        return False
    return os.getuid() != 0


@functools.cache
def _prctl_call():
    prctl = ctypes.CDLL(None, use_errno=True).prctl
    prctl.argtypes = [ctypes.c_int] + [ctypes.c_ulong] * 4
    return prctl


def _prctl(option: int, *args: int) -> int:
    try:
        return _prctl_call()(option, *args, *[0] * (4 - len(args)))
    except (OSError, AttributeError):
        return -1


def _second_user_namespace() -> bool:
    uid, gid = os.getuid(), os.getgid()
    try:
        if isolation.libc().unshare(isolation.CLONE_NEWUSER) != 0:
            return False
    except (OSError, AttributeError):
        return False
    isolation.map_ids(uid, gid)
    return True


class _Program(ctypes.Structure):   # struct sock_fprog
    _fields_ = [("len", ctypes.c_ushort), ("filter", ctypes.c_void_p)]


@functools.cache
def _filter_program():
    """The filter as libseccomp compiles it (classic BPF), compiled once in the runner and
    inherited: compiling it in each worker cost 0.8 ms a job. None without libseccomp."""
    lib = _seccomp()
    ctx = lib.seccomp_init(SCMP_ACT_ALLOW) if lib is not None else None
    if not ctx:
        return None
    try:
        for name in DENIED_CALLS:
            _deny(lib, ctx, name, errno.EPERM)
        for flag in NAMESPACE_FLAGS:
            _deny(lib, ctx, "clone", errno.EPERM, _ArgCmp(0, SCMP_CMP_MASKED_EQ, flag, flag))
        _deny(lib, ctx, "clone3", errno.ENOSYS)
        fd = os.memfd_create("rippleb-seccomp")
        try:
            if lib.seccomp_export_bpf(ctx, fd) != 0:
                return None
            code = os.pread(fd, 1 << 20, 0)
        finally:
            os.close(fd)
    finally:
        lib.seccomp_release(ctx)
    buffer = ctypes.create_string_buffer(code, len(code))
    return buffer, _Program(len(code) // 8, ctypes.addressof(buffer))


def _seccomp_filter() -> bool:
    program = _filter_program()
    return program is not None and _prctl(PR_SET_SECCOMP, SECCOMP_MODE_FILTER, ctypes.addressof(program[1])) == 0


def _deny(lib, ctx, name: str, code: int, *conditions: _ArgCmp) -> None:
    number = lib.seccomp_syscall_resolve_name(name.encode())
    if number >= 0:   # a call this kernel's architecture lacks needs no rule
        array = (_ArgCmp * max(1, len(conditions)))(*conditions)
        lib.seccomp_rule_add_array(ctx, SCMP_ACT_ERRNO(code), number, len(conditions), array)


def _drop_capabilities() -> bool:
    _prctl(PR_CAP_AMBIENT, PR_CAP_AMBIENT_CLEAR_ALL)
    for cap in range(_last_capability() + 1):
        _prctl(PR_CAPBSET_DROP, cap)
    header = (ctypes.c_uint32 * 2)(0x20080522, 0)      # _LINUX_CAPABILITY_VERSION_3, this process
    empty = (ctypes.c_uint32 * 6)()                   # effective, permitted, inheritable; 2 words each
    return _syscall(SYS_CAPSET, header, empty) == 0


@functools.cache
def _last_capability() -> int:
    try:
        with open("/proc/sys/kernel/cap_last_cap") as fh:
            return int(fh.read())
    except (OSError, ValueError):
        return 63


def say_missing(sealed: bool) -> None:
    """Once per run of the local pool: one warning naming the protections this kernel does
    not grant a method's process; for a sealed run (new or resumed), refusal instead."""
    missing = missing_protections()
    if not missing:
        return
    lacking = "; ".join(missing)
    if sealed:
        raise InputError(f"--sealed needs every wall around a method's process, and this kernel does not grant "
                         f"{lacking}; a method could reach the salt: run sealed comparisons where it does "
                         f"(docs/robustness.md, sections 10 and 11)")
    warnings.warn(f"this kernel does not grant a method's process {lacking}: it can reach more than "
                  f"docs/robustness.md says (sections 10 and 11)", RunWarning, stacklevel=3)


def missing_protections() -> tuple[str, ...]:
    """What this kernel does not grant a method's worker, asked anew each run (a fork, 20 ms):
    a forked keeper-like child takes the namespaces, and its child the worker's own steps
    (mounts, :func:`lock_down`), and reports what failed."""
    read_fd, write_fd = os.pipe()
    pid = os.fork()
    if pid == 0:
        try:
            os.close(read_fd)
            _probe(write_fd)
        finally:
            os._exit(0)
    os.close(write_fd)
    with os.fdopen(read_fd, "rb") as fh:
        found = fh.read().decode()
    os.waitpid(pid, 0)
    tasks.remove(pid)
    return tuple(line for line in found.splitlines() if line)


def _probe(write_fd: int) -> None:
    capped = tasks.enter(MAX_TASKS + 1) is not None
    granted = isolation.new_namespaces()
    missing = [] if granted.pid else ["a user and PID namespace"]
    if granted.pid and not granted.mount:
        missing.append("a mount namespace")
    if not granted.net:
        missing.append("a network namespace (the network closed)")
    worker = os.fork()   # a new PID namespace holds this process's children, not itself
    if worker == 0:
        if granted.mount:
            missing += isolation.confine_files(())
        missing += lock_down(None, nested_namespace=granted.mount, own_proc=granted.mount, own_users=granted.pid,
                             capped=capped)
        os.write(write_fd, "\n".join(missing).encode())
        os._exit(0)
    os.close(write_fd)
    os.waitpid(worker, 0)


with contextlib.suppress(OSError, AttributeError, ImportError):   # made in the runner, inherited by every worker
    _filter_program()
    tasks.pids_root()
    landlock.library_paths()
    landlock.abi()
    _prctl_call()
    _last_capability()
