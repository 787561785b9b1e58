"""Atomic file replacement, shared by every writer of rippleb."""

from __future__ import annotations

import contextlib
import os
import secrets
from pathlib import Path
from typing import Iterator

from rippleb.errors import InputError


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success, move it over ``path`` at once.

    A reader, a SIGINT or a ``kill -9`` therefore sees the old file or the new one,
    never half of one. The temporary name keeps ``path``'s suffix (``np.savez`` adds
    ``.npz`` otherwise). An ``OSError`` becomes an :class:`InputError` naming ``path``.
    """
    path = Path(path)
    if path.parent.exists() and not path.parent.is_dir():
        # said before a writer names its temporary file: pyarrow's error quotes that name
        raise InputError(f"{path}: cannot write: {path.parent} is not a directory")
    # A unique temporary name: two writers of one path never share a temporary file.
    tmp = path.with_name(f".{path.name}.{os.getpid()}-{secrets.token_hex(4)}.tmp{path.suffix}")
    try:
        yield tmp
        tmp.replace(path)
    except OSError as exc:
        with contextlib.suppress(OSError):  # e.g. the parent is a regular file: no tmp exists
            tmp.unlink(missing_ok=True)
        raise InputError(f"{path}: cannot write: {exc.strerror or exc}") from None


def refuse_links(directory: Path, names, also_in: str | None = None) -> None:
    """Refuse a directory where an entry rippleb writes (``names``, and any entry of the
    subdirectory ``also_in``) is a symbolic link: rippleb makes none, and writing through
    one would truncate or fill the file it names, anywhere the user may write (issue 34; a
    report's ``figures/`` a link once put its figures outside, issue 41). One line naming
    the first."""
    directory = Path(directory)
    found = [directory / name for name in names if (directory / name).is_symlink()]
    inner = directory / also_in if also_in else None
    if not found and inner is not None and inner.is_dir():
        found = [entry for entry in sorted(inner.iterdir()) if entry.is_symlink()][:1]
    if found:
        raise InputError(f"{found[0]}: a symbolic link, which rippleb never makes in a run or report "
                         f"directory; rippleb does not write through it: remove it, or choose another --out")


def open_appending(path: str | Path, encoding: str = "utf-8"):
    """``path`` opened to append text (created if absent), never through a symbolic link:
    a link put in place of a run directory's file must not lead rippleb's writes to the
    file it names (issue 34). ``OSError`` (``ELOOP`` for a link) is the caller's."""
    fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, 0o644)
    return open(fd, "a", encoding=encoding)
