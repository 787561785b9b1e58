"""What a finished job becomes in a row: the fields a job may set, and why one ended without a
result, in one line.

A job's own message is untrusted (a method's process wrote it): :func:`row_fields` takes
only the typed fields a job may set. How a job ended (:class:`rippleb.engine.process.pool.Finished`)
is said by :func:`why`, with an environmental cause first (:func:`environment_first`),
where ``--resume`` looks for it.
"""

from __future__ import annotations

import math
import signal

from rippleb.engine.results import ENVIRONMENT, STATUSES


def row_fields(info: dict) -> dict:
    """The fields a job may set, type-checked: a job cannot write metrics or keys."""
    status = info.get("status") if info.get("status") in STATUSES else "error"
    fields = {"status": status, "message": str(info.get("message", ""))[:500],
              "params": str(info.get("params", ""))[:2000]}
    fit_s = info.get("fit_s")
    if isinstance(fit_s, (int, float)) and math.isfinite(fit_s):
        fields["fit_s"] = float(fit_s)
    if status != info.get("status"):
        fields["message"] = f"the row sent an unknown status {str(info.get('status'))[:40]!r}"
    return fields


def environment_first(message: str) -> str:
    """Move an environmental marker to the front, where ``--resume`` looks for it."""
    if ENVIRONMENT in message and not message.startswith(ENVIRONMENT):
        return ENVIRONMENT + message.replace(ENVIRONMENT, "", 1)
    return message


def why(fin, timeout: float | None) -> str:
    """Why a job ended without a result it could use, in one line (``timeout``: the limit
    it was ended at); a cause outside the method (a full disk, a SIGKILL from outside)
    starts with :data:`~rippleb.engine.results.ENVIRONMENT`, so ``--resume`` runs it again."""
    if fin.kind == "raised":
        text = fin.value
        if any(marker in text for marker in ("No space left", "Disk quota")):
            return f"{ENVIRONMENT}{text}"
        return text
    if fin.kind == "timeout":
        return f"killed after {timeout:g} s"
    if fin.kind == "oversized":
        return f"sent {fin.value} bytes, more than a row's result can hold"
    if fin.kind == "garbled":
        return (f"its process wrote into rippleb's control pipe ({bytes(fin.value)!r}...); "
                "the job was ended and its result discarded")
    code = fin.value
    if code is not None and code < 0:
        try:
            name = signal.Signals(-code).name
        except ValueError:
            name = f"number {-code}"
        if -code == signal.SIGKILL:  # not our timeout: the OOM killer or a user
            return f"{ENVIRONMENT}process killed by {name} (out of memory, or killed from outside)"
        return f"process killed by signal {name} (a crash?)"
    return f"process exited with code {code} before reporting"
