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
3. **Landlock** (landlock(7)): writing, creating, removing and renaming files is denied
   everywhere but beneath the job's scratch directory (a tmpfs of its own,
   :data:`rippleb.engine.process.isolation.SCRATCH_OPTIONS`) and ``/dev/null``: the rippleb
   package, site-packages, ``$HOME``, the run directory and the cache are read-only.
4. **seccomp** through libseccomp (the library behind Docker's, systemd's and Flatpak's
   filters): :data:`DENIED_CALLS` fail with ``EPERM``, a ``clone`` that asks for a new
   namespace too, and ``clone3`` (whose flags a filter cannot read) with ``ENOSYS``, which
   makes the C library fall back to ``clone``.
5. **No capabilities**: the bounding and ambient sets are emptied, then the effective,
   permitted and inheritable sets.

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
import warnings

from rippleb.engine.process import isolation
from rippleb.errors import InputError, RunWarning

#: Calls no method needs that would let it reach past its walls: mounts (old and new API),
#: tracing other processes or reading their memory, new or other namespaces, kernel BPF
#: programs, the kernel keyrings, performance counters.
DENIED_CALLS = ("mount", "umount2", "pivot_root", "move_mount", "open_tree", "fsopen", "fsmount", "fsconfig",
                "fspick", "mount_setattr", "ptrace", "process_vm_readv", "process_vm_writev", "unshare",
                "setns", "bpf", "keyctl", "add_key", "request_key", "perf_event_open")
#: ``clone`` flags that ask for a new namespace (sched.h).
NAMESPACE_FLAGS = (0x00020000, 0x02000000, 0x04000000, 0x08000000, 0x10000000, 0x20000000, 0x40000000)

PR_SET_NO_NEW_PRIVS, PR_CAPBSET_DROP, PR_CAP_AMBIENT, PR_CAP_AMBIENT_CLEAR_ALL = 38, 24, 47, 4
PR_SET_SECCOMP, SECCOMP_MODE_FILTER = 22, 2
SYS_CAPSET = 126   # x86-64
SYS_LANDLOCK_CREATE_RULESET, SYS_LANDLOCK_ADD_RULE, SYS_LANDLOCK_RESTRICT_SELF = 444, 445, 446
LANDLOCK_CREATE_RULESET_VERSION, LANDLOCK_RULE_PATH_BENEATH = 1, 1
# landlock(7) file system rights: what changes a file or a directory's entries.
LL_WRITE_FILE, LL_TRUNCATE, LL_REFER = 1 << 1, 1 << 14, 1 << 13
LL_CHANGES_ENTRIES = sum(1 << bit for bit in (4, 5, 6, 7, 8, 9, 10, 11, 12))   # remove_*, make_*
SCMP_ACT_ALLOW = 0x7FFF0000
SCMP_CMP_MASKED_EQ = 7


def SCMP_ACT_ERRNO(code: int) -> int:   # noqa: N802 - libseccomp's name
    return 0x00050000 | (code & 0xFFFF)


class _ArgCmp(ctypes.Structure):
    _fields_ = [("arg", ctypes.c_uint), ("op", ctypes.c_int), ("datum_a", ctypes.c_uint64),
                ("datum_b", ctypes.c_uint64)]


class _PathBeneath(ctypes.Structure):
    _pack_ = 1
    _fields_ = [("allowed_access", ctypes.c_uint64), ("parent_fd", ctypes.c_int32)]


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


def lock_down(scratch: str | None, nested_namespace: bool) -> list[str]:
    """Apply every step this kernel grants (module docstring) to this process; return what
    it could not, one phrase each (empty when all held). ``scratch``: the one directory
    this process may write; ``nested_namespace``: keep its mounts out of its reach (only
    where it runs in a user namespace of rippleb's, with mounts to keep)."""
    missing = []
    if nested_namespace and not _second_user_namespace():
        missing.append("a second user namespace (mounts it cannot undo)")
    if _prctl(PR_SET_NO_NEW_PRIVS, 1) != 0:
        missing.append("no-new-privileges")
    if not _landlock(scratch):
        missing.append("Landlock (a read-only file system but its scratch directory)")
    if not _seccomp_filter():
        missing.append("a seccomp filter (libseccomp)")
    if not _drop_capabilities():
        missing.append("an empty capability set")
    return missing


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


def _landlock(scratch: str | None) -> bool:
    abi = _syscall(SYS_LANDLOCK_CREATE_RULESET, None, ctypes.c_size_t(0),
                   ctypes.c_uint32(LANDLOCK_CREATE_RULESET_VERSION))
    if abi < 1:
        return False
    file_rights = LL_WRITE_FILE | (LL_TRUNCATE if abi >= 3 else 0)
    handled = ctypes.c_uint64(file_rights | LL_CHANGES_ENTRIES | (LL_REFER if abi >= 2 else 0))
    ruleset = _syscall(SYS_LANDLOCK_CREATE_RULESET, ctypes.byref(handled), ctypes.c_size_t(8), ctypes.c_uint32(0))
    if ruleset < 0:
        return False
    try:
        allowed = [(scratch, handled.value)] if scratch else []
        allowed.append((os.devnull, file_rights))
        for path, rights in allowed:
            if not _allow_beneath(ruleset, path, rights):
                return False
        return _syscall(SYS_LANDLOCK_RESTRICT_SELF, ctypes.c_int(ruleset), ctypes.c_uint32(0)) == 0
    finally:
        os.close(ruleset)


def _allow_beneath(ruleset: int, path: str, rights: int) -> bool:
    try:
        fd = os.open(path, os.O_PATH | os.O_CLOEXEC)
    except OSError:
        return False
    try:
        rule = _PathBeneath(rights, fd)
        return _syscall(SYS_LANDLOCK_ADD_RULE, ctypes.c_int(ruleset), ctypes.c_int(LANDLOCK_RULE_PATH_BENEATH),
                        ctypes.byref(rule), ctypes.c_uint32(0)) == 0
    finally:
        os.close(fd)


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


def wipe_command_line() -> None:
    """Zero this process's command line (``/proc/self/cmdline``): a forked worker inherits
    the runner's, which names ``--salt-file FILE`` in a resumed sealed run. The runner's
    own copy is untouched: the worker's pages are its own once written."""
    try:
        with open("/proc/self/stat", "rb") as fh:
            fields = fh.read().rsplit(b")", 1)[1].split()
        start, end = int(fields[45]), int(fields[46])   # arg_start, arg_end: fields 48, 49 of proc(5)
    except (OSError, ValueError, IndexError):
        return
    if 0 < start < end:
        ctypes.memset(start, 0, end - start)


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
                         f"(docs/robustness.md, section 10)")
    warnings.warn(f"this kernel does not grant a method's process {lacking}: it can reach more than "
                  f"docs/robustness.md says (section 10)", RunWarning, stacklevel=3)


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
    return tuple(line for line in found.splitlines() if line)


def _probe(write_fd: int) -> None:
    isolated, own_mounts = isolation.new_namespaces()
    missing = [] if isolated else ["a user and PID namespace"]
    if isolated and not own_mounts:
        missing.append("a mount namespace")
    worker = os.fork()   # a new PID namespace holds this process's children, not itself
    if worker == 0:
        if isolated and own_mounts:
            missing += isolation.confine_files(())
        missing += lock_down(None, nested_namespace=isolated and own_mounts)
        os.write(write_fd, "\n".join(missing).encode())
        os._exit(0)
    os.close(write_fd)
    os.waitpid(worker, 0)


with contextlib.suppress(OSError, AttributeError):   # made in the runner, inherited by every worker
    _filter_program()
    _prctl_call()
    _last_capability()
