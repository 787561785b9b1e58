"""What rippleb reads, bounded: file kinds, sizes, links and nesting, each refused in one line.

Every file rippleb reads from a user (a scenario, a joint file, a log, a salt file, its
key) or from a run directory (``run.json``, ``results.csv``, ``rows.mac``,
``provenance.json``) goes through :func:`read_bytes` (or, for a log that pandas reads
itself, :func:`check_file`) with a cap of its own:

* only a regular file is read: a FIFO would block the reader until someone writes to it
  (it is opened without blocking, then refused), ``/dev/zero`` or ``/dev/urandom`` never
  end, a directory is no file;
* at most ``cap`` bytes are read, and a larger file is refused before any byte of it is
  (``rows.mac`` or ``run.json`` a link to ``/dev/zero`` once read 5.4 GB);
* in a run directory (``in_run_dir``) a symbolic link is not followed (``O_NOFOLLOW``):
  rippleb makes none there, and one put in place of its files would make a report or a
  ``--resume`` read whatever it names. A user's own file may be a link: it is read as
  what it names, with the same checks.

:func:`parse_json` and :func:`parse_toml` parse what was read and refuse a document
nested deeper than :data:`MAX_NESTING` (Python's parsers recurse per level and ended in a
``RecursionError`` traceback) or that does not parse, naming the file. The caps and why
each is generous for real use are in docs/robustness.md, section 11.
"""

from __future__ import annotations

import errno
import json
import os
import stat
import tomllib
from pathlib import Path

from rippleb.errors import InputError

KIB, MIB, GIB = 2**10, 2**20, 2**30
#: ``results.csv``: 4 GiB, six million rows of the published comparison's 690 bytes, three
#: times :data:`rippleb.engine.rows.MAX_ROWS`, so a run's own file fits with long messages.
RESULTS_BYTES = 4 * GIB
#: ``rows.mac``: 65 bytes a row, so 256 MiB holds twice :data:`~rippleb.engine.rows.MAX_ROWS`.
LEDGER_BYTES = 256 * MIB
#: ``run.json`` and ``provenance.json``: 10 000 seeds, a sweep's values and a tuning record
#: are tens of kilobytes (the published run's 12 kB).
RUN_FILE_BYTES = 16 * MIB
#: A scenario or a joint file: a scenario of 1000 segments (its most) is about 100 kB.
TOML_BYTES = 1 * MIB
#: A recorded log, CSV or Parquet: 4 GiB is twenty million samples of seven CSV columns,
#: twice the longest simulated scenario; :data:`rippleb.log_files.MAX_LOG_SAMPLES` bounds the rows.
LOG_BYTES = 4 * GIB
#: A salt file (64 hex digits) or rippleb's key (32 bytes).
SECRET_BYTES = 4 * KIB
#: How deep a JSON or TOML document may nest: rippleb's own files nest at most 6 deep.
MAX_NESTING = 32

#: The joint values rippleb accepts (a scenario's ``[joint]``, a log's joint file): beyond
#: them a value describes no harmonic-drive joint, and its numbers overflow or divide by
#: nothing into ``ok`` rows. docs/robustness.md, section 11, gives each bound's reason.
JOINT_RANGES = {"fs": (100.0, 1.0e6), "control_rate": (10.0, 1.0e6), "gear_ratio": (1.0, 1000.0),
                "counts_per_rev": (1, 2**24), "rated_torque": (0.01, 1.0e5), "torque_constant": (1.0e-4, 100.0),
                "rotor_inertia": (1.0e-10, 10.0)}


def check_joint_value(key: str, value, where: str):
    """``value`` of joint field ``key`` if within :data:`JOINT_RANGES`, else one line naming ``where``."""
    low, high = JOINT_RANGES[key]
    if not value > 0:
        raise InputError(f"{where}: must be positive, got {value!r}")
    if not low <= value <= high:
        raise InputError(f"{where}: must be in [{low:g}, {high:g}] (docs/robustness.md, section 11), got {value:g}")
    return value


_KINDS = ((stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
          (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"), (stat.S_ISDIR, "a directory"))


def size_text(n: int) -> str:
    """``2 GiB``, ``16 MiB``, ``4 KiB`` or bytes."""
    for unit, size in (("GiB", GIB), ("MiB", MIB), ("KiB", KIB)):
        if n >= size and n % size == 0:
            return f"{n // size} {unit}"
    return f"{n} bytes"


def _kind(mode: int) -> str:
    return next((name for test, name in _KINDS if test(mode)), "not a regular file")


def _open(path: Path, what: str, in_run_dir: bool) -> int:
    flags = os.O_RDONLY | os.O_CLOEXEC | os.O_NONBLOCK | (os.O_NOFOLLOW if in_run_dir else 0)
    try:
        return os.open(path, flags)
    except OSError as exc:
        if exc.errno == errno.ELOOP and in_run_dir:
            raise InputError(f"{path}: a symbolic link, which rippleb never makes in a run directory; "
                             f"rippleb does not read through it: remove it") from None
        if exc.errno == errno.ENOENT:
            raise FileNotFoundError(errno.ENOENT, exc.strerror, str(path)) from None
        raise InputError(f"{path}: cannot read the {what}: {exc.strerror or exc}") from None


def _check_stat(path: Path, st: os.stat_result, cap: int, what: str) -> None:
    if not stat.S_ISREG(st.st_mode):
        raise InputError(f"{path}: {_kind(st.st_mode)}, not a regular file; rippleb reads a {what} from "
                         f"a regular file only")
    if st.st_size > cap:
        raise InputError(f"{path}: {st.st_size} bytes, more than the {size_text(cap)} a {what} may have "
                         f"(docs/robustness.md, section 11)")


def read_bytes(path, cap: int, what: str, *, in_run_dir: bool = False) -> bytes:
    """The bytes of the regular file ``path``, at most ``cap`` of them.

    Raises :class:`InputError` (naming ``path``, ``what`` it is and the cap) for anything
    else: another kind of file, a larger one, a symbolic link where ``in_run_dir``, a read
    error. A missing file raises ``FileNotFoundError``, which each caller words itself.
    """
    path = Path(path)
    fd = _open(path, what, in_run_dir)
    try:
        _check_stat(path, os.fstat(fd), cap, what)
        chunks, size = [], 0
        while size <= cap:   # a file that grows while it is read is still bounded
            chunk = os.read(fd, min(8 * MIB, cap + 1 - size))
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
    except OSError as exc:
        raise InputError(f"{path}: cannot read the {what}: {exc.strerror or exc}") from None
    finally:
        os.close(fd)
    if size > cap:
        raise InputError(f"{path}: more than the {size_text(cap)} a {what} may have (it grew while read)")
    return b"".join(chunks)


def read_text(path, cap: int, what: str, *, in_run_dir: bool = False, encoding: str = "utf-8") -> str:
    """:func:`read_bytes` decoded; a file that is not ``encoding`` is one line naming it."""
    data = read_bytes(path, cap, what, in_run_dir=in_run_dir)
    try:
        return data.decode(encoding)
    except UnicodeDecodeError as exc:
        raise InputError(f"{path}: cannot read the {what}: {exc}") from None


def check_file(path, cap: int, what: str) -> None:
    """Refuse, before a library opens it, a ``path`` that is not a regular file of at most
    ``cap`` bytes (a log that pandas reads); a missing one raises ``FileNotFoundError``."""
    path = Path(path)
    fd = _open(path, what, in_run_dir=False)
    try:
        _check_stat(path, os.fstat(fd), cap, what)
    finally:
        os.close(fd)


def read_table(path: Path, max_rows: int, what: str):
    """A CSV or Parquet file as a pandas DataFrame, refused beyond ``max_rows`` rows with one
    line (a Parquet file's row count is in its footer and may be far more than its bytes;
    a CSV is read no further than one row past it), and any file pandas cannot read too."""
    import pandas as pd
    import pyarrow.parquet as pq

    csv = path.suffix.lower() == ".csv"
    try:
        if not csv:
            with pq.ParquetFile(path) as file:
                rows = file.metadata.num_rows
            if rows > max_rows:
                raise InputError(f"{path}: {rows} rows, more than the {max_rows} rows a {what} may hold "
                                 f"(docs/robustness.md, section 11); split it")
        frame = pd.read_csv(path, nrows=max_rows + 1) if csv else pd.read_parquet(path)
    except InputError:
        raise
    except Exception as exc:  # pandas and Arrow raise many types for unreadable files
        raise InputError(f"{path}: cannot read as {'csv' if csv else 'parquet'}: "
                         f"{str(exc).splitlines()[0] if str(exc) else type(exc).__name__}") from None
    if len(frame) > max_rows:
        raise InputError(f"{path}: more than the {max_rows} rows a {what} may hold "
                         f"(docs/robustness.md, section 11); split it")
    return frame


def duplicated_columns(path: Path, names_of_interest) -> list[str]:
    """The columns among ``names_of_interest`` named more than once in a CSV or Parquet
    file's header (pandas would rename the second ``strain`` to ``strain.1`` and read the
    first alone; Arrow refuses to choose)."""
    try:
        if path.suffix.lower() == ".csv":
            import pandas as pd

            names = [str(n) for n in pd.read_csv(path, header=None, nrows=1, dtype=str).iloc[0]]
        else:
            import pyarrow.parquet as pq

            names = pq.read_schema(path).names
    except Exception:  # noqa: BLE001 - unreadable: the read itself says why, naming the file
        return []
    return sorted({n for n in names if n in names_of_interest and names.count(n) > 1})


def nesting(value) -> int:
    """How deep lists and tables nest in a parsed document (a scalar: 0)."""
    deepest, level, todo = 0, 0, [(value, 0)]
    while todo:
        value, level = todo.pop()
        if isinstance(value, (dict, list)):
            level += 1
            deepest = max(deepest, level)
            todo.extend((v, level) for v in (value.values() if isinstance(value, dict) else value))
    return deepest


def _nested(path, value):
    if nesting(value) > MAX_NESTING:
        raise InputError(f"{path}: nested more than {MAX_NESTING} levels deep; rippleb's files nest a few")
    return value


def parse_json(text: str, path) -> object:
    """A JSON document read from ``path``; not JSON, or nested too deep, is one line."""
    try:
        return _nested(path, json.loads(text))
    except RecursionError:
        raise InputError(f"{path}: nested more than {MAX_NESTING} levels deep; rippleb's files nest a few") from None
    except ValueError as exc:   # not JSON, or an integer of more than 4300 digits
        raise InputError(f"{path}: not valid JSON: {str(exc)[:200]}") from None


def parse_toml(text: str, path) -> dict:
    """A TOML document read from ``path``; not TOML, or nested too deep, is one line."""
    try:
        return _nested(path, tomllib.loads(text))
    except RecursionError:
        raise InputError(f"{path}: nested more than {MAX_NESTING} levels deep; rippleb's files nest a few") from None
    except ValueError as exc:   # TOMLDecodeError, or an integer of more than 4300 digits
        raise InputError(f"{path}: not valid TOML: {str(exc)[:200]}") from None
