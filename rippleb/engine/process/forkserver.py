"""The fork server: the process every job of a local run is forked from.

Why: a job forked from the runner would inherit the runner's memory, and the runner holds
the truth of every case with rows in flight (it scores them). A method that searched its
own process (its stack frames, ``gc.get_objects()``, the raw heap) would find the truth it
is scored on. The fork server is forked from the runner when a run starts, before the
first simulation, so no truth ever exists in it. The runner sends it each job as data
(:class:`rippleb.engine.jobs.Job`, pickled by the runner: trusted bytes) with the job's two pipe
ends attached; the server forks a keeper for it (:func:`rippleb.engine.process.keeper.keeper`, which forks
the worker exactly as before) and replies with the keeper's PID. What a job returns still
goes straight to the runner through its pipe.

The server holds what every job needs and nothing else: the registry (inherited at the
fork) and the modules the runner had imported. It never runs plugin code itself: plugins
are imported by the workers, as before.

Protocol over a Unix stream socket pair: the runner sends an 8-byte length with the two
pipe ends attached (``SCM_RIGHTS``), then the pickled ``(job, memory_mb, output, confine)``; the
server answers with the keeper's PID (8 bytes). The server reaps its keepers, exits when
the runner closes its end, and is killed by the kernel if the runner dies first
(``PR_SET_PDEATHSIG``).

No side waits for ever (issue 25): the runner waits for the server's answer only while the
server lives and no signal has come (:mod:`rippleb.interrupts`), and for its exit at most
:data:`EXIT_GRACE_S` before it kills it; the server, once the runner has closed its end,
waits for its keepers at most :data:`KEEPERS_GRACE_S` before it kills them
(each keeper ends its worker as soon as the runner closes the job's pipes, so this is the
last resort); a keeper's worker dies with it.
"""

from __future__ import annotations

import contextlib
import os
import pickle
import select
import signal
import socket
import struct
import sys
import threading
import time

from rippleb import interrupts
from rippleb.engine.process import hugepages, isolation, tasks

_LENGTH = struct.Struct("!Q")
_PID = struct.Struct("!q")
#: How long the server may wait for its keepers once the runner has closed it [s] ...
KEEPERS_GRACE_S = 5.0
#: ... and how long the runner waits for the server to exit before killing it [s].
EXIT_GRACE_S = KEEPERS_GRACE_S + 2.0
#: How often a wait for the server looks for a signal or the server's death [s].
POLL_S = 0.2


class ForkServer:
    """The runner's handle on a fork server (see the module docstring).

    Use :meth:`start` in a ``with`` block; :meth:`spawn` starts one job.
    """

    def __init__(self, sock: socket.socket, pid: int):
        self.sock = sock
        self.pid = pid
        self._lock = threading.Lock()  # one request at a time (a Dask worker has threads)

    @classmethod
    def start(cls, context, preload=None) -> "ForkServer":
        """Fork the server; every job it runs is called as ``job(context)``.

        ``preload()``, if given, runs in the server before its first job: imports and
        loads that every job would otherwise repeat (rippleb's own code only, never a
        plugin's: the server is the parent of every job).
        """
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
        sys.stdout.flush()
        sys.stderr.flush()
        pid = os.fork()
        if pid == 0:
            try:
                ours.close()
                _serve(theirs, context, preload)
            finally:
                os._exit(0)
        theirs.close()
        return cls(ours, pid)

    def spawn(self, job, result_w: int, ctrl_w: int, memory_mb, output, confine=None) -> int:
        """Have the server fork a keeper for ``job`` writing to the given pipe ends;
        returns the keeper's PID (not a child of this process: the server reaps it)."""
        payload = pickle.dumps((job, memory_mb, output, confine), protocol=pickle.HIGHEST_PROTOCOL)
        with self._lock:
            socket.send_fds(self.sock, [_LENGTH.pack(len(payload))], [result_w, ctrl_w])
            self.sock.sendall(payload)
            self._await_answer()
            return _PID.unpack(_recv_exact(self.sock, _PID.size))[0]

    def _await_answer(self) -> None:
        """Wait until the server's answer can be read: it may still be loading modules
        (``preload``, seconds on a fresh install). Raises ``KeyboardInterrupt`` if a signal
        arrives meanwhile and ``ConnectionError`` if the server has died."""
        while not select.select([self.sock], [], [], POLL_S)[0]:
            interrupts.check_interrupted()
            if not self.alive():
                raise ConnectionError("fork server: died before it answered")

    def alive(self) -> bool:
        """True while the server runs (it is this process's child)."""
        if self.sock.fileno() < 0:
            return False
        try:
            pid, _ = os.waitpid(self.pid, os.WNOHANG)
        except ChildProcessError:
            return False
        return pid == 0

    def close(self) -> None:
        """Let the server exit (it reaps its keepers first) and reap it; kill it if it
        has not exited within :data:`EXIT_GRACE_S` (its keepers and their workers die
        with it)."""
        if self.sock.fileno() < 0:
            return
        self.sock.close()
        with interrupts.held():
            if not isolation.wait_exit(self.pid, EXIT_GRACE_S):
                with contextlib.suppress(ProcessLookupError):
                    os.kill(self.pid, signal.SIGKILL)
                with contextlib.suppress(ChildProcessError):
                    os.waitpid(self.pid, 0)  # SIGKILL cannot be caught: this returns at once

    def __enter__(self) -> "ForkServer":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _serve(sock: socket.socket, context, preload) -> None:
    """The server's loop: one keeper per request until the runner closes the socket."""
    from rippleb.engine.process.keeper import Bound, keeper

    isolation.die_with_parent()
    isolation.name_process("rippleb-server")
    # Ctrl-C reaches the whole foreground process group: the runner handles it (it ends
    # the jobs and closes this server); SIGTERM from the runner's handler kills us plainly.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    if preload is not None:
        try:
            preload()
        except Exception:  # noqa: BLE001 - only a head start: each job loads what it needs anyway
            pass
    hugepages.collapse_private_memory()  # cheaper forks and exits of every job (module docstring)
    keepers: set[int] = set()
    while True:
        keepers.difference_update(_reaped())
        request = _receive(sock)
        if request is None:
            break
        (job, memory_mb, output, confine), (result_w, ctrl_w) = request
        pid = os.fork()
        if pid == 0:
            sock.close()
            isolation.die_with_parent()  # the server is single-threaded: its death ends the job
            keeper(Bound(job, context, always=True), result_w, ctrl_w, memory_mb, output, confine)  # never returns
        keepers.add(pid)
        os.close(result_w)
        os.close(ctrl_w)
        sock.sendall(_PID.pack(pid))
    _reap_all(keepers, KEEPERS_GRACE_S)


def _receive(sock: socket.socket):
    """The next request, or None once the runner has closed its end."""
    try:
        head, fds, _, _ = socket.recv_fds(sock, _LENGTH.size, 2)
    except OSError:  # the runner is gone
        return None
    if not head:
        return None
    head += _recv_exact(sock, _LENGTH.size - len(head))
    job = pickle.loads(_recv_exact(sock, _LENGTH.unpack(head)[0]))
    return job, tuple(fds)


def _recv_exact(sock: socket.socket, n: int) -> bytes:
    chunks, got = [], 0
    while got < n:
        chunk = sock.recv(min(n - got, 1 << 20))
        if not chunk:
            raise ConnectionError("fork server: the other end closed mid-message")
        chunks.append(chunk)
        got += len(chunk)
    return b"".join(chunks)


def _reap_all(keepers: set[int], grace_s: float) -> None:
    """Reap every keeper still running; kill those still there after ``grace_s``.

    The runner has closed the server: normally every job has ended, and a keeper whose
    job the runner gave up ends its worker as soon as it sees the job's pipes closed.
    """
    deadline = time.monotonic() + grace_s
    while keepers and time.monotonic() < deadline:
        keepers.difference_update(_reaped())
        if keepers:
            time.sleep(0.01)
    for pid in keepers:
        for kill in (os.killpg, os.kill):  # its session, or the keeper alone if it has none yet
            with contextlib.suppress(ProcessLookupError, PermissionError):
                kill(pid, signal.SIGKILL)
    while True:
        try:
            tasks.remove(os.waitpid(-1, 0)[0])  # every keeper left was killed: each wait returns at once
        except ChildProcessError:
            return
        except InterruptedError:
            continue


def _reaped() -> list[int]:
    """The keepers that have exited, reaped, their process groups removed."""
    pids = isolation.reap_exited()
    for pid in pids:
        tasks.remove(pid)
    return pids
