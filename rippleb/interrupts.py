"""Ctrl-C and SIGTERM: when they may stop the runner, and when they only leave a note.

A signal's Python handler runs wherever the main thread happens to be. Raising
``KeyboardInterrupt`` there is what makes Ctrl-C work during start-up (imports, scenario
checks, Dask's blocking calls), but in the middle of starting a job it orphans it: a keeper
already forked by the fork server whose pipes the runner no longer tracks, a worker blocked
writing its result into a pipe nobody reads, and the runner, fork server and keeper each
waiting for the next (issue 25). So a signal is handled in one of two ways:

* **raised** at once (the default, and inside :func:`raising`), the first time only: a
  second Ctrl-C must not break off the cleanup the first one started;
* **held** inside :func:`held`: recorded, and raised by the next :func:`check_interrupted`,
  which the runner calls only where stopping leaves nothing half done (between jobs, and
  in every wait, which polls).

:func:`handling` installs the handler for SIGINT and SIGTERM (so both end a run with its
finished rows kept); :func:`ignore_from_now` is for a program whose command is over.
"""

from __future__ import annotations

import contextlib
import signal
import threading

#: Signals received since :func:`handling` was entered (outermost).
_RECEIVED: list[int] = []
#: How deep in :func:`held` blocks we are (signals are then recorded only) ...
_HELD = [0]
#: ... and whether a KeyboardInterrupt has been raised for a signal already.
_RAISED = [False]


def _handler(signum, frame):
    _RECEIVED.append(signum)
    if not _HELD[0] and not _RAISED[0]:
        _RAISED[0] = True
        raise KeyboardInterrupt(f"signal {signum}")




def received() -> bool:
    """True once SIGINT or SIGTERM has arrived (inside :func:`handling`)."""
    return bool(_RECEIVED)


def check_interrupted() -> None:
    """Raise ``KeyboardInterrupt`` if a signal has arrived.

    Call it only where stopping leaves nothing half done. It raises again even if the
    handler raised already: an exception raised inside a callback whose exceptions are
    printed and dropped (an at-fork handler, a ``__del__``) is lost, and a run that got
    here goes on.
    """
    if _RECEIVED:
        _RAISED[0] = True
        raise KeyboardInterrupt(f"signal {_RECEIVED[0]}")


@contextlib.contextmanager
def held():
    """Record signals without raising them in this block (a job being started or ended,
    a file replaced, the run directory claimed). They are raised by the next
    :func:`check_interrupted`; the block itself never raises for them.

    Only the main thread holds: handlers run there, and another thread (a Dask worker's
    task) holding would change what the main thread does."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _HELD[0] += 1
    try:
        yield
    finally:
        _HELD[0] -= 1


@contextlib.contextmanager
def raising():
    """Raise signals at once again inside a :func:`held` block: for waits in code rippleb
    does not control (Dask's client), which only an exception can break off."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    depth, _HELD[0] = _HELD[0], 0
    try:
        check_interrupted()
        yield
    finally:
        _HELD[0] = depth


def _installed() -> bool:
    return signal.getsignal(signal.SIGTERM) is _handler


@contextlib.contextmanager
def handling():
    """Treat SIGTERM like Ctrl-C and record both, for the block (re-entrant: an inner block
    keeps the outer one's record). A SIGINT that is ignored (a background process) stays
    ignored. Outside the main thread, signals are left alone."""
    if _installed():
        yield
        return
    try:
        previous = install()
    except ValueError:  # not the main thread
        yield
        return
    try:
        yield
    finally:
        for signum, old in previous.items():
            signal.signal(signum, old)
        _reset()


def hold_from_start(early: list[int] = ()) -> None:
    """Install the handler with signals held, for the ``rippleb`` program
    (``rippleb/__init__.py`` calls this), so that a signal during its imports is recorded
    rather than raised where no one can report it; ``early`` are the signals the package's
    first lines noted before this module loaded. :func:`install`, in
    :func:`rippleb.cli.entry`, ends the hold and keeps the record."""
    if not _installed():
        _reset()
        _HELD[0] += 1   # first: a signal right after the handler is in place is held
        signal.signal(signal.SIGTERM, _handler)
        if signal.getsignal(signal.SIGINT) is not signal.SIG_IGN:   # ignored: a background process
            signal.signal(signal.SIGINT, _handler)
    _RECEIVED.extend(early)


def install() -> dict:
    """Install the handler for SIGTERM, and for SIGINT unless it is ignored; return the
    handlers it replaced. If :func:`hold_from_start` installed it already, end its hold
    and keep what it recorded (:func:`check_interrupted` raises it)."""
    if _installed():
        _HELD[0] = 0
        return {}
    _reset()
    previous = {signal.SIGTERM: signal.signal(signal.SIGTERM, _handler)}
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        previous[signal.SIGINT] = signal.signal(signal.SIGINT, _handler)
    return previous


def ignore_from_now() -> None:
    """Ignore SIGINT and SIGTERM for the rest of this process: its command is over and
    its status decided. (Python resets a Python-level handler to the default action while
    it shuts down, so a late Ctrl-C would otherwise kill the process or print a traceback.)

    Also forget a ``KeyboardInterrupt`` that escaped code run through ``PyRun_String``
    (Boost.Python's ``exec``, which Pinocchio's import runs): Python remembers it and, at
    exit, kills itself with SIGINT, even though rippleb caught the exception and chose its
    exit status. A successful ``PyRun_SimpleString`` clears that memory.
    """
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    with contextlib.suppress(Exception):
        import ctypes

        ctypes.pythonapi.PyRun_SimpleString(b"pass")


def _reset() -> None:
    _RECEIVED.clear()
    _HELD[0] = 0
    _RAISED[0] = False
