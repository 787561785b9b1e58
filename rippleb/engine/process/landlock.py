"""What a method's process may read and write, and whom it may reach: one Landlock ruleset.

A method reads only what it is handed (issue 41, item 2): its blocks and its calibration
log (given to its process before the walls go up, :mod:`rippleb.engine.jobs`), its own
package and the libraries. Landlock (landlock(7), Linux 5.13 and later) enforces it with
the kernel's own rules, which the process cannot drop nor widen once it has restricted
itself, whatever capabilities it holds:

* **reading** (files, directory listings, programs to execute) only beneath
  :func:`library_paths` (the Python installation and its site-packages, rippleb's own
  package, the system's library and program directories), the method's own package, a few
  files and devices every library may ask for (:data:`DEVICES`, :data:`FILES`), the CPU
  description in ``/sys`` and its own ``/proc``; so the recorded logs, the run directory,
  other rows, the cache, ``$HOME``, ``/etc`` and a sealed run's salt (its file, a copy of it
  anywhere) are unreadable;
* **writing**, creating, removing and renaming only beneath its scratch directory
  (and ``/dev/null``);
* **TCP**: no connect and no bind on any port (ABI 4 and later): the second wall beside
  the network namespace of :func:`rippleb.engine.process.isolation.new_namespaces`;
* **scopes** (ABI 6 and later): no abstract Unix socket and no signal outside its own
  processes.

Only ``stat`` and the walk through directories stay open (Landlock does not govern them):
a method can learn that a path exists, never what it holds.
"""

from __future__ import annotations

import ctypes
import functools
import importlib.util
import os
import site
import sys

from rippleb.engine.process import isolation

SYS_CREATE_RULESET, SYS_ADD_RULE, SYS_RESTRICT_SELF = 444, 445, 446
CREATE_RULESET_VERSION, RULE_PATH_BENEATH, RULE_NET_PORT = 1, 1, 2
# landlock(7) file system rights
EXECUTE, WRITE_FILE, READ_FILE, READ_DIR = 1 << 0, 1 << 1, 1 << 2, 1 << 3
CHANGES_ENTRIES = sum(1 << bit for bit in range(4, 13))   # remove_*, make_*
REFER, TRUNCATE = 1 << 13, 1 << 14
# network rights (ABI 4) and scopes (ABI 6)
BIND_TCP, CONNECT_TCP = 1 << 0, 1 << 1
SCOPE_ABSTRACT_UNIX_SOCKET, SCOPE_SIGNAL = 1 << 0, 1 << 1

#: Directories of programs and shared libraries a library may load (``dlopen`` of a part
#: not yet loaded, ``ctypes.util.find_library`` running ``ldconfig``); on a merged ``/usr``
#: the top-level ones are links into it.
SYSTEM_PATHS = ("/usr", "/lib", "/lib64", "/lib32", "/libx32", "/bin", "/sbin", "/opt")
#: Devices any library may open: no data of anyone's in them.
DEVICES = ("/dev/zero", "/dev/urandom", "/dev/random", "/dev/full")
#: Files of ``/etc`` that the C library reads to load a shared library or tell the time:
#: the loader's cache of library paths and the zone; nothing of any user's.
FILES = ("/etc/ld.so.cache", "/etc/localtime")
#: What the CPU is, which OpenBLAS, numba and ``os.cpu_count`` ask ``/sys``.
SYS_PATHS = ("/sys/devices/system/cpu", "/sys/devices/system/node")


class _RulesetAttr(ctypes.Structure):
    _fields_ = [("handled_access_fs", ctypes.c_uint64), ("handled_access_net", ctypes.c_uint64),
                ("scoped", ctypes.c_uint64)]


class _PathBeneath(ctypes.Structure):
    _pack_ = 1
    _fields_ = [("allowed_access", ctypes.c_uint64), ("parent_fd", ctypes.c_int32)]


def _syscall(*args) -> int:
    libc = isolation.libc()
    libc.syscall.restype = ctypes.c_long
    return libc.syscall(*args)


@functools.cache
def abi() -> int:
    """The Landlock ABI this kernel offers (0: none)."""
    try:
        return max(0, _syscall(SYS_CREATE_RULESET, None, ctypes.c_size_t(0), ctypes.c_uint32(CREATE_RULESET_VERSION)))
    except (OSError, AttributeError):
        return 0


@functools.cache
def library_paths() -> tuple[str, ...]:
    """Where the code a method may run lives: the Python installation (its prefixes and
    site-packages, the user's own site-packages when Python reads it), rippleb's package
    (with ``rippleb.methods`` and ``rippleb.scenarios``, wherever an editable install put
    them) and :data:`SYSTEM_PATHS`. Computed once, in the runner, and inherited."""
    paths = [sys.prefix, sys.exec_prefix, sys.base_prefix, sys.base_exec_prefix, *site.getsitepackages()]
    if site.ENABLE_USER_SITE and site.getusersitepackages() in sys.path:
        paths.append(site.getusersitepackages())
    for package in ("rippleb", "rippleb.methods", "rippleb.scenarios"):
        paths += package_paths(package)
    return tuple(dict.fromkeys(os.path.realpath(p) for p in [*paths, *SYSTEM_PATHS] if os.path.exists(p)))


def own_package(registry, label: str) -> tuple[str, ...]:
    """What a method's process may read beyond the libraries: the package of the method
    ``label`` names (a variant's label, ``name[p=v]``, names its method)."""
    from rippleb.variants import parse_label

    try:
        return package_paths(registry.get(parse_label(label).name).module)
    except Exception:  # noqa: BLE001 - an unknown name fails its job, which says why
        return ()


def package_paths(module: str) -> tuple[str, ...]:
    """The directories of ``module``'s top-level package, or its file if it is a lone module,
    found without importing it (``importlib.util.find_spec`` of a top-level name runs no
    code of the package; a module imported already is asked where it came from). Empty if
    it cannot be found."""
    top = module.split(".")[0] if module.split(".")[0] != "rippleb" else module
    loaded = sys.modules.get(top)
    if loaded is not None and (getattr(loaded, "__path__", None) or getattr(loaded, "__file__", None)):
        return tuple(str(p) for p in getattr(loaded, "__path__", None) or [loaded.__file__])
    try:
        spec = importlib.util.find_spec(top)
    except (ImportError, ValueError):
        return ()
    if spec is None:
        return ()
    if spec.submodule_search_locations:
        return tuple(str(p) for p in spec.submodule_search_locations)
    return (spec.origin,) if spec.origin and os.path.exists(spec.origin) else ()


def restrict(scratch: str | None, readable=(), own_proc: bool = True, reads: bool = True) -> list[str]:
    """Restrict this process (and what it forks) to the module docstring's rules; return
    what this kernel could not enforce, one phrase each (empty when all held).

    ``scratch``: the one directory it may write; ``readable``: what it may read beyond
    the libraries (its own package); ``own_proc``: ``/proc`` shows its own PID namespace
    only, so all of it is readable (else only its own entry). ``reads`` False leaves reading
    and the network open, as issue 34's walls did (``benchmarks/confine_overhead.py``
    measures what closing them costs)."""
    version = abi()
    if version < 1:
        return ["Landlock (reads and writes confined)"]
    write = WRITE_FILE | (TRUNCATE if version >= 3 else 0)
    read = READ_FILE | READ_DIR | EXECUTE if reads else 0
    fs = read | write | CHANGES_ENTRIES | (REFER if version >= 2 else 0)
    net = BIND_TCP | CONNECT_TCP if version >= 4 and reads else 0
    scoped = SCOPE_ABSTRACT_UNIX_SOCKET | SCOPE_SIGNAL if version >= 6 and reads else 0
    attr = _RulesetAttr(fs, net, scoped)
    size = 24 if version >= 6 else 16 if version >= 4 else 8
    ruleset = _syscall(SYS_CREATE_RULESET, ctypes.byref(attr), ctypes.c_size_t(size), ctypes.c_uint32(0))
    if ruleset < 0:
        return ["Landlock (reads and writes confined)"]
    proc = ("/proc",) if own_proc else (f"/proc/{os.getpid()}", "/proc/cpuinfo", "/proc/meminfo", "/proc/stat")
    rules = [(path, read) for path in (*library_paths(), *readable, *SYS_PATHS, *proc, *FILES, *DEVICES) if read]
    # The directory that holds the method's package may be listed, not read: Python's import
    # system finds a module by listing the directories of sys.path.
    rules += [(os.path.dirname(path.rstrip("/")), READ_DIR) for path in readable if read]
    rules += [(os.devnull, read | write)] + ([(scratch, fs)] if scratch else [])
    try:
        for path, rights in rules:
            if not _allow(ruleset, path, rights) and path in (scratch, os.devnull):
                return ["Landlock (reads and writes confined)"]
        if _syscall(SYS_RESTRICT_SELF, ctypes.c_int(ruleset), ctypes.c_uint32(0)) != 0:
            return ["Landlock (reads and writes confined)"]
    finally:
        os.close(ruleset)
    if not reads:
        return []
    missing = [] if net else ["Landlock's network rules (Linux 6.7)"]
    return missing + ([] if scoped else ["Landlock's scopes (Linux 6.12)"])


def _allow(ruleset: int, path: str, rights: int) -> bool:
    """Add a rule for ``path`` (a file takes only the rights that apply to files); False
    when the path is missing or the kernel refuses it."""
    try:
        fd = os.open(path, os.O_PATH | os.O_CLOEXEC)
    except OSError:
        return False
    try:
        if not os.path.isdir(path):
            rights &= EXECUTE | WRITE_FILE | READ_FILE | TRUNCATE
        rule = _PathBeneath(rights, fd)
        return _syscall(SYS_ADD_RULE, ctypes.c_int(ruleset), ctypes.c_int(RULE_PATH_BENEATH),
                        ctypes.byref(rule), ctypes.c_uint32(0)) == 0
    finally:
        os.close(fd)
