"""Deployment conditions: what happened to a joint between calibration and scoring.

A condition is the fourth axis of a result row (method x scenario x condition x seed).
The calibration log is always recorded in the *first* session of the device; the
condition says what changed before the scored session was recorded. Each condition's
physics and magnitudes are documented in ``docs/physics.md`` ("Deployment conditions").
"""

from __future__ import annotations

from rippleb.errors import InputError
from rippleb.registry import unknown_name

#: name -> one-line description (shown by ``rippleb list``)
CONDITIONS = {
    "same-session": "calibrated just before scoring, same power-on: the most favourable case",
    "power-cycled": "powered off and on: the incremental encoder counts from an arbitrary "
                    "start, the session may run at another temperature",
    "aged": "months of use since calibration: ripple amplitudes, phases and bridge zero drifted",
    "re-assembled": "flexspline re-mounted or drive swapped: gauge errors (ripple, gain) redrawn",
}
DEFAULT_CONDITION = "same-session"


def check_condition(name: str) -> str:
    """Return ``name`` if it is a known condition, else raise one clear line."""
    if name not in CONDITIONS:
        raise InputError(unknown_name("condition", name, list(CONDITIONS)))
    return name
