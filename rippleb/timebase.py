"""A recorded log's time base: its unit, its sample rate, gaps, jitter and resampling.

A DAQ stamps samples in seconds, milliseconds, microseconds or Unix time (epoch); rippleb
works in seconds from the first sample. The sample rate is that of the DAQ's clock: the
sample periods from the first stamp to the last over their span (:func:`uniform_rate`),
a dropped sample's period counted (:func:`sample_periods`). Not one over the median step:
Unix time held in a float64 is quantized to 2.4e-7 s, so the steps of a 20 kHz log
alternate between 49.8 and 50.1 us and the median step said 19 972.9 Hz; the span says
20 000 Hz. Nor ``(n - 1) / (t[-1] - t[0])`` alone: 2 % of isolated dropped samples in a
20 kHz log said 19 600 Hz.

A step longer than :data:`JITTER_LIMIT` times the median is not a sample period. Up to
:data:`GAP_LIMIT` times it, it is timing jitter (a DAQ that stamps samples in software,
or one dropped sample): :func:`resample` puts the log on a uniform grid on request.
Beyond, samples are missing: nothing is invented, the log is refused.
"""

from __future__ import annotations

import numpy as np

from rippleb.errors import InputError

#: Units of column ``t`` and their factor to seconds; the epoch units are also rebased to 0.
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9, "epoch": 1.0, "epoch_ms": 1e-3}
#: A ``t`` in seconds whose first stamp is beyond this is Unix time (1e8 s is 3.2 years;
#: no recording starts that late after its own zero, every Unix date since 1973 does).
EPOCH_START_S = 1e8
#: Longest step, in median steps, of a log read as it is (the limit before this work).
JITTER_LIMIT = 1.5
#: Longest step, in median steps, that :func:`resample` bridges: jitter, or one dropped sample
#: (a step of 2) with jitter on top. A longer one is a gap in the recording.
GAP_LIMIT = 2.5


def to_seconds(t: np.ndarray, unit: str) -> np.ndarray:
    """``t`` in seconds; Unix time (``epoch``, ``epoch_ms``) rebased to start at 0.

    Rebasing keeps the stamps a method sees small; the rate does not depend on it. It comes
    before the scaling, which then rounds the small differences, not the large stamps."""
    t = np.asarray(t, dtype=float)
    if unit.startswith("epoch") and len(t):
        t = t - t[0]
    return t * TIME_UNITS[unit]


def looks_like_epoch(t: np.ndarray) -> bool:
    """True when a ``t`` in seconds starts at a Unix date rather than near 0."""
    return len(t) > 0 and float(t[0]) >= EPOCH_START_S


def sample_periods(t: np.ndarray) -> int:
    """Sample periods from the first stamp to the last: one per step, and one more for each
    sample a step dropped.

    A step of :data:`JITTER_LIMIT` median steps or more is a dropped sample, or a stamp
    that came late: a late stamp makes the step after it short, and the two together span
    two periods; a dropped sample's step spans two periods between steps of one. So a long
    step adds ``round(min(its sum with either neighbour) / median) - 2`` periods: 1 for a
    dropped sample, 0 for jitter.
    """
    steps = np.diff(np.asarray(t, float))
    if not len(steps):
        return 0
    median = float(np.median(steps))
    extra = 0
    for i in np.flatnonzero(steps >= JITTER_LIMIT * median):
        pairs = [steps[j] + steps[i] for j in (i - 1, i + 1) if 0 <= j < len(steps)]
        extra += max(0, int(round(min(pairs, default=2 * steps[i]) / median)) - 2)
    return len(steps) + extra


def uniform_rate(t: np.ndarray) -> float:
    """The rate of the DAQ's clock [Hz]: :func:`sample_periods` over the span from the first
    stamp to the last; NaN below two samples.

    On a log without dropped samples it is ``(n - 1) / (t[-1] - t[0])``, the mean rate (the
    stamps' own jitter cancels in the span); a dropped sample adds its period, so it does
    not move the rate.
    """
    t = np.asarray(t, float)
    if len(t) < 2 or not t[-1] > t[0]:
        return float("nan")
    return sample_periods(t) / float(t[-1] - t[0])


def check_steps(t: np.ndarray, source: str, *, resampling: bool = False) -> None:
    """Refuse a ``t`` with a gap, or, unless ``resampling``, with jitter (module docstring).

    ``t`` must already strictly increase. The line names ``source`` and the first bad row.
    """
    steps = np.diff(t)
    if not len(steps):
        return
    median = float(np.median(steps))
    gap = steps > GAP_LIMIT * median
    if gap.any():
        row = int(np.argmax(gap)) + 1
        raise InputError(f"{source}: column t has a gap of {steps[row - 1]:.6g} s at row {row} "
                         f"(sample period {median:.6g} s); rippleb needs an unbroken log")
    jitter = steps > JITTER_LIMIT * median
    if jitter.any() and not resampling:
        row = int(np.argmax(jitter)) + 1
        raise InputError(f"{source}: column t has a step of {steps[row - 1]:.6g} s at row {row}, "
                         f"{steps[row - 1] / median:.2f} sample periods ({median:.6g} s): timing jitter "
                         f"or a dropped sample; pass --resample to put the log on a uniform grid at its "
                         f"clock's rate ({uniform_rate(t):.6g} Hz), docs/your-joint.md")


def resample(columns: dict[str, np.ndarray], held: tuple[str, ...] = ("encoder",),
             pulses: tuple[str, ...] = ("index",)) -> dict[str, np.ndarray]:
    """``columns`` on the uniform grid ``t0 + k (t[-1] - t0) / K``, ``k = 0 .. K``.

    The grid keeps the log's first and last stamp; ``K`` is the number of sample periods
    between them at the clock's rate (:func:`sample_periods`), so a dropped sample gets its
    grid point back and the grid's rate is the clock's. Measured values (strain, current,
    torques) are interpolated linearly between their two neighbouring samples; ``held``
    columns (encoder counts, integers a DAQ latches) take the last sample at or before each
    grid time; a ``pulses`` column (the index pulse, 0/1) keeps each pulse, moved to the
    grid time nearest to it.
    """
    t = np.asarray(columns["t"], float)
    grid = np.linspace(t[0], t[-1], max(1, sample_periods(t)) + 1)
    out = {"t": grid}
    latest = np.clip(np.searchsorted(t, grid, side="right") - 1, 0, len(t) - 1)
    for name, values in columns.items():
        if name == "t" or values is None:
            continue
        values = np.asarray(values)
        if name in held:
            out[name] = values[latest]
        elif name in pulses:
            out[name] = _moved_pulses(t, grid, values)
        else:
            out[name] = np.interp(grid, t, values.astype(float))
    return out


def _moved_pulses(t: np.ndarray, grid: np.ndarray, pulses: np.ndarray) -> np.ndarray:
    moved = np.zeros(len(grid), dtype=pulses.dtype)
    at = t[np.asarray(pulses) != 0]
    right = np.clip(np.searchsorted(grid, at), 1, len(grid) - 1)
    nearest = np.where(np.abs(grid[right - 1] - at) <= np.abs(grid[right] - at), right - 1, right)
    moved[nearest] = 1
    return moved
