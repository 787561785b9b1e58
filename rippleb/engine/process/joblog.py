"""A job's output, bounded: the worker writes into a pipe, its keeper copies it into the log.

A method's worker once opened its own log and wrote to it without bound (issue 34: a
method that printed 300 MB left a 301 MB log per row, and a log path that was a symbolic
link truncated the file it pointed to). Now the keeper, rippleb's code, opens the log
(never through a symbolic link: ``O_NOFOLLOW``) before it forks the worker, gives the
worker only the writing end of a pipe as its stdout and stderr, and copies at most
:data:`OUTPUT_CAP_BYTES` into the log; the rest is read and dropped, so the worker never
blocks, and one line at the end says how much was dropped.
"""

from __future__ import annotations

import contextlib
import os

#: What one job may leave in its log [bytes]: 8 MiB, thousands of times a chatty method's
#: log (a built-in method's row writes none; a traceback is a few kB) and small enough that
#: a run of thousands of rows cannot fill a disk with logs.
OUTPUT_CAP_BYTES = 8 * 2**20
_CHUNK = 1 << 16


class JobLog:
    """The keeper's end of a job's output: a pipe to read, a log to fill up to the cap.

    Parameters
    ----------
    path
        The log file (made or emptied), or None to drop the output.
    """

    def __init__(self, path: str | None):
        self.path = path
        self.read_fd, self.write_fd = os.pipe()
        self.log_fd = None
        self.kept = 0
        self.dropped = 0

    def open(self) -> None:
        """Open the log, never through a symbolic link; a log that cannot be opened
        (a link put in its place, a full disk) leaves the output dropped."""
        os.set_blocking(self.read_fd, False)
        if self.path is not None:
            with contextlib.suppress(OSError):
                self.log_fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_NOFOLLOW
                                      | os.O_CLOEXEC, 0o644)

    def give_to_worker(self) -> None:
        """In the worker: stdin from /dev/null, stdout and stderr into the pipe."""
        null = os.open(os.devnull, os.O_RDONLY)
        os.dup2(null, 0)
        os.close(null)
        os.dup2(self.write_fd, 1)
        os.dup2(self.write_fd, 2)
        os.close(self.write_fd)
        os.close(self.read_fd)
        if self.log_fd is not None:
            os.close(self.log_fd)

    def drain(self) -> bool:
        """Copy what the pipe holds now; False once every writer has closed it."""
        while True:
            try:
                chunk = os.read(self.read_fd, _CHUNK)
            except BlockingIOError:
                return True
            except OSError:
                return False
            if not chunk:
                return False
            self._keep(chunk)

    def _keep(self, chunk: bytes) -> None:
        room = max(0, OUTPUT_CAP_BYTES - self.kept)
        if room and self.log_fd is not None:
            with contextlib.suppress(OSError):   # a full disk costs the log, never the row
                write_all(self.log_fd, chunk[:room])
        self.kept += min(room, len(chunk))
        self.dropped += len(chunk) - min(room, len(chunk))

    def close(self) -> None:
        """Drain what is left, say what was dropped, close the log."""
        self.drain()
        if self.log_fd is not None:
            if self.dropped:
                note = (f"\nrippleb: this job wrote {self.kept + self.dropped} bytes; its log keeps the first "
                        f"{OUTPUT_CAP_BYTES} ({OUTPUT_CAP_BYTES // 2**20} MiB), {self.dropped} bytes were dropped\n")
                with contextlib.suppress(OSError):
                    write_all(self.log_fd, note.encode())
            os.close(self.log_fd)
            self.log_fd = None
        os.close(self.read_fd)


def write_all(fd: int, data: bytes) -> None:
    """Write all of ``data`` to ``fd`` (a pipe or a file takes part of it at a time)."""
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view):]
