"""The columns of a log: their names and the per-channel strain columns.

A log has the sensor columns, optional ones, and the truth of a simulation
(:data:`LOG_COLUMNS`). A gauge layout with several amplifier channels
(:mod:`rippleb.layouts`) logs each channel [V] beside ``strain``, their mean: in a file as
``strain_1 .. strain_K``, in memory as :attr:`rippleb.data.SensorLog.channels` (samples x
channels). Recorded logs may carry them too (docs/your-joint.md).

Examples
--------
>>> from rippleb.log_columns import channel_columns
>>> channel_columns(["t", "strain", "strain_2", "strain_1"])
('strain_1', 'strain_2')
"""

from __future__ import annotations

import re

from rippleb.errors import InputError

SENSOR_COLUMNS = ("t", "strain", "encoder", "current")
#: Optional sensor columns: ``index`` is 1 on samples where the encoder's once-per-revolution
#: index pulse is seen, else 0 (simulated logs have it; recorded logs may).
OPTIONAL_SENSOR_COLUMNS = ("index",)
TRUTH_COLUMNS = ("torque_true", "torque_ref")
LOG_COLUMNS = SENSOR_COLUMNS + OPTIONAL_SENSOR_COLUMNS + TRUTH_COLUMNS
#: A channel's column is this and its number, from 1 (docs/physics.md, "Gauges on the
#: flexspline").
CHANNEL_PREFIX = "strain_"
#: Most channels a log may carry: far above any layout (a ring of 9 elements), low enough
#: that a file of thousands of ``strain_k`` columns is refused rather than read.
MAX_CHANNELS = 64
_CHANNEL = re.compile(r"strain_([1-9][0-9]*)")


def channel_names(count: int) -> tuple[str, ...]:
    """``("strain_1", ..., "strain_<count>")``: the file columns of ``count`` channels."""
    return tuple(f"{CHANNEL_PREFIX}{k}" for k in range(1, count + 1))


def is_channel(name: str) -> bool:
    """Whether ``name`` is a channel's column, ``strain_1`` .. ``strain_<MAX_CHANNELS>``."""
    match = _CHANNEL.fullmatch(str(name))
    return bool(match) and int(match.group(1)) <= MAX_CHANNELS


def channel_columns(names, source: str = "log") -> tuple[str, ...]:
    """The channel columns among ``names`` (``strain_1`` .. ``strain_K``), in order; a set
    with a gap, or more than :data:`MAX_CHANNELS`, is one :class:`InputError` naming
    ``source``."""
    numbers = sorted(int(m.group(1)) for m in map(_CHANNEL.fullmatch, map(str, names)) if m)
    if not numbers:
        return ()
    if len(numbers) > MAX_CHANNELS or numbers[-1] > MAX_CHANNELS:
        raise InputError(f"{source}: {max(len(numbers), numbers[-1])} strain channels; at most "
                         f"{MAX_CHANNELS} (strain_1 .. strain_{MAX_CHANNELS})")
    if numbers != list(range(1, len(numbers) + 1)):
        missing = sorted(set(range(1, numbers[-1] + 1)) - set(numbers))
        raise InputError(f"{source}: strain channels must be strain_1 .. strain_K without a gap; "
                         f"{CHANNEL_PREFIX}{missing[0]} is missing")
    return channel_names(len(numbers))

