"""Re-homing an incremental encoder count on its index pulse.

A ripple map fitted on a calibration log is a function of the absolute motor angle, but an
incremental counter starts wherever it stood at power-on. The index pulse (log column
``index``) marks one fixed count edge per revolution: :func:`index_mark` finds it in the
calibration log, :class:`IndexHoming` maps a later run's counts back into the calibration
frame at every pulse. Used by ``kalman-ripple``; a private module (leading underscore), so
method discovery skips it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


def index_mark(encoder: np.ndarray, index, counts_per_rev: int):
    """Count (mod ``counts_per_rev``) of the encoder's index mark in this log's frame, or
    None without index pulses.

    The mark is the count edge crossed at a pulse: ``max`` of the counts of the pulse
    sample and the one before, when they are one count apart. Pulses crossed with skipped
    counts are ambiguous and left out; the most common value wins (a count error in the
    log would otherwise move it).
    """
    if index is None:
        return None
    pulses = np.flatnonzero(index)
    pulses = pulses[pulses > 0]
    steps = encoder[pulses] - encoder[pulses - 1]
    clean = pulses[np.abs(steps) == 1]
    if len(clean) == 0:
        return None
    marks = np.maximum(encoder[clean], encoder[clean - 1]) % counts_per_rev
    values, counts = np.unique(marks, return_counts=True)
    return int(values[np.argmax(counts)])


@dataclass
class IndexHoming:
    """The counts of one run in the calibration frame, re-homed at each index pulse.

    Parameters
    ----------
    mark
        Count of the index mark in the calibration frame (:func:`index_mark`), or None:
        no re-homing, counts pass unchanged.
    counts_per_rev
        Encoder counts per motor revolution.

    At a pulse the mark lies between the counts of the pulse sample and the sample
    before it. One count apart (below fs counts/s) that fixes the frame exactly; when the
    DAQ skipped counts it fixes it to the skipped range. The current frame is kept
    whenever the mark falls inside that range (so a joint still in its calibration
    session's power-on keeps its frame), else the middle of the range is taken. Until the
    first pulse the counts are taken as they come.
    """

    mark: int | None
    counts_per_rev: int
    shift: int = 0                # logged count minus calibration-frame count
    homed: bool = False           # a pulse has been seen in this run
    last: int | None = field(default=None, repr=False)   # last logged count

    def counts(self, encoder: np.ndarray, index, start: int):
        """``(counts in the calibration frame, pulse)`` for one block.

        ``start`` is the absolute sample index of ``encoder[0]``; ``pulse`` is the absolute
        index of the pulse at which the first homing of the run moved the frame, else None.
        """
        pulses = None if index is None or self.mark is None else np.flatnonzero(index)
        if pulses is None or len(pulses) == 0:
            if len(encoder):
                self.last = encoder[-1]
            return (encoder - self.shift if self.shift else encoder), None
        shift = np.full(len(encoder), self.shift, dtype=np.int64)
        n, moved = self.counts_per_rev, None
        for k in pulses:
            before = encoder[k - 1] if k else (encoder[k] if self.last is None else self.last)
            lo, hi = sorted((int(before), int(encoder[k])))
            lo = min(lo + 1, hi)   # the mark is the edge below one of the counts lo..hi
            if (self.mark + self.shift - lo) % n > hi - lo:   # the frame is off
                if not self.homed:
                    moved = start + int(k)
                self.shift = (lo + (hi - lo) // 2 - self.mark) % n
            self.homed = True
            shift[k:] = self.shift
        self.last = encoder[-1]
        return encoder - shift, moved
