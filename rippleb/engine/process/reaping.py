"""Keepers that have ended their job: reaped without holding up the next one.

A keeper that has reported its worker's exit has cleaned up already and has only to exit
(:mod:`rippleb.engine.process.keeper`); the pool leaves it to exit on its own and reaps it
later (:data:`EXITING`), so the runner starts the next job instead of waiting. A keeper that
overstays its grace, or one that never reported, is ended with its whole session.
"""

from __future__ import annotations

import atexit
import contextlib
import os
import signal
import time

from rippleb.engine.process import tasks

KEEPER_GRACE_S = 5.0


#: Keepers whose job has ended and that have only to exit: ``(pid, when to stop waiting)``.
#: Shared by every pool of the process (a Dask worker runs one pool per row), reaped by
#: the next pool call and at exit.
EXITING: list[tuple[int, float]] = []


def reap_exiting(block: bool = False) -> None:
    """Reap the keepers of :data:`EXITING` that have exited (all of them if ``block``);
    end any that overstays its grace."""
    now = time.monotonic()
    still = []
    for pid, deadline in EXITING:
        try:
            if os.waitpid(pid, os.WNOHANG)[0]:
                tasks.remove(pid)
                continue
        except ChildProcessError:  # reaped already
            continue
        if block or now > deadline:
            wait_keeper(pid, max(0.0, deadline - now))
        else:
            still.append((pid, deadline))
    EXITING[:] = still


atexit.register(reap_exiting, True)


def wait_keeper(keeper: int, grace_s: float = KEEPER_GRACE_S) -> None:
    """Reap ``keeper``; if it has not exited within ``grace_s``, end its whole session."""
    deadline = time.monotonic() + grace_s
    while True:
        pid, _ = os.waitpid(keeper, os.WNOHANG)
        if pid or time.monotonic() > deadline:
            break
        time.sleep(0.005)
    if not pid:  # the keeper did not finish its cleanup in time: end its whole session
        kill_keeper(keeper)
        os.waitpid(keeper, 0)  # SIGKILL cannot be caught: this returns at once
    tasks.remove(keeper)


def kill_keeper(keeper: int) -> None:
    """SIGKILL a keeper and its session (one not yet in a session of its own, too)."""
    for kill in (os.killpg, os.kill):
        with contextlib.suppress(ProcessLookupError, PermissionError):
            kill(keeper, signal.SIGKILL)
