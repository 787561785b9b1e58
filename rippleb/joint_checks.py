"""Checks that catch a wrong joint description before a recorded log is scored.

A joint file states what a log cannot say; some of it the log can still contradict. Each
check reads the log alone and either says what it found (a note beside the value in the
block ``rippleb run --log`` prints) or refuses the log in one line naming the value:

* **counts per revolution** against the encoder's index pulse: it marks one place on the
  motor's revolution, so two pulses crossed in one direction are ``counts_per_rev`` counts
  apart (:func:`index_spacing`). Without an index, a single-turn encoder's counts wrap at
  its range (:func:`wrap_range`); counts that neither pulse nor wrap cannot be checked, and
  the note says so.
* **the strain's unit** against the calibration log's: the calibrated strain of the scored
  log must be a torque the joint can carry (:func:`check_strain_scale`), else no method that
  reads the strain can be scored on it (strain in V labelled mV reads 1000 times too large).
* **the gear ratio**: nothing in a log measures it; the note says which estimates use it.

The sample rate has its own rule (:func:`rippleb.timebase.uniform_rate`).
"""

from __future__ import annotations

import numpy as np

from rippleb.errors import InputError

#: Two index pulses closer than this many counts are the same mark crossed back and forth
#: (a reversal at the mark, or the edge's own jitter), not a revolution apart.
SAME_MARK_COUNTS = 16
#: The relative difference between the measured and the stated counts per revolution that
#: refuses the log. Encoder edge errors and a counter's missed counts move the spacing by a
#: count or two in thousands; a wrong encoder resolution moves it by tens of per cent.
COUNTS_TOLERANCE = 0.01
#: What the gear ratio is used for, said beside it (it cannot be read from a log).
GEAR_RATIO_NOTE = ("no log can check it: of the built-in methods only current-based reads it (to turn "
                   "motor current into joint torque); no score uses it")


def index_spacing(encoder: np.ndarray, index: np.ndarray | None) -> np.ndarray:
    """Counts between consecutive index pulses that lie a revolution (or more) apart:
    ``abs(diff(encoder at the pulses))``, without the steps below :data:`SAME_MARK_COUNTS`."""
    if index is None:
        return np.zeros(0)
    at = np.asarray(encoder)[np.asarray(index) != 0].astype(np.int64)
    steps = np.abs(np.diff(at))
    return steps[steps >= SAME_MARK_COUNTS]


def wrap_range(encoder: np.ndarray) -> int | None:
    """The range a single-turn encoder's counts wrap at, ``max - min + 1``, if the counts jump
    by more than half of it within one sample (a wrap); None if they never do."""
    counts = np.asarray(encoder, dtype=np.int64)
    if len(counts) < 2:
        return None
    span = int(counts.max() - counts.min()) + 1
    if span < 2 * SAME_MARK_COUNTS or not (np.abs(np.diff(counts)) > span // 2).any():
        return None
    return span


def check_counts(counts_per_rev: int, encoder: np.ndarray, index: np.ndarray | None,
                 source: str, stated: str) -> str:
    """What the log says of ``counts_per_rev`` (a note), or an :class:`InputError` that starts
    with ``stated``: the value and where it came from (the joint file's key, or the default)."""
    spacing = index_spacing(encoder, index)
    if len(spacing):
        measured = float(np.median(spacing))
        near = spacing[np.abs(spacing - measured) <= 0.1 * measured]
        seen = f"{near.min()}-{near.max()}" if near.min() != near.max() else f"{near.min()}"
        if abs(measured - counts_per_rev) > COUNTS_TOLERANCE * counts_per_rev:
            raise InputError(f"{stated}, but {source}'s index pulses are "
                             f"{seen} counts apart ({len(spacing)} revolutions): the encoder has "
                             f"{measured:.0f} counts per revolution; give counts_per_rev = {measured:.0f} "
                             f"(docs/your-joint.md)")
        return f"agrees with the index pulses, {seen} counts apart"
    wrap = wrap_range(encoder)
    if wrap is not None:
        if abs(wrap - counts_per_rev) > COUNTS_TOLERANCE * counts_per_rev:
            raise InputError(f"{stated}, but {source}'s encoder counts wrap "
                             f"at {wrap}: a single-turn encoder of {wrap} counts per revolution; give "
                             f"counts_per_rev = {wrap} and unwrap the counts (docs/your-joint.md)")
        raise InputError(f"{source}: column encoder wraps at {wrap} counts (a single-turn encoder): rippleb "
                         f"needs a count that runs on over revolutions; unwrap it, e.g. "
                         f"numpy.unwrap(counts, period={wrap})")
    return "not checked: the log has no index pulse and its counts do not wrap"


def check_strain_scale(strain: np.ndarray, calibration, torque_limit: float, source: str,
                       strain_unit: str) -> None:
    """Refuse a scored log whose strain, calibrated as the calibration log's, is no torque the
    joint carries (its peak beyond ``torque_limit``): the two logs' strain units differ.

    ``strain_unit`` says how the scored log's strain column was read (for the message)."""
    from rippleb.dsp import fit_gain_offset

    gain, offset = fit_gain_offset(calibration.strain, calibration.torque_ref)
    peak = float(np.max(np.abs(gain * np.asarray(strain, float) + offset)))
    if peak > torque_limit:
        raise InputError(f"{source}: column strain ({strain_unit}): calibrated as the calibration log's strain, "
                         f"it reads up to {peak:.4g} Nm, beyond {torque_limit:g} Nm, the most a joint of this "
                         f"rated torque carries: the two logs' strain units differ (strain in V labelled mV "
                         f"reads 1000 times too large); give each log's unit in [joint.columns] or its sidecar "
                         f"(docs/your-joint.md)")


def notes(log, description, source: str, *, spec_given: bool = False) -> dict[str, str]:
    """The checks of one log read with ``description``: per key, the note its line gets in
    the block ``rippleb run --log`` prints; a value the log contradicts is an :class:`InputError`."""
    key, counts = "counts_per_rev", int(log.spec.counts_per_rev)
    if spec_given:
        stated = f"{source}: read with read_log's spec, counts_per_rev = {counts}"
    elif key in description.sources:
        stated = f"{description.sources[key]}: joint.{key}: {counts}"
    else:
        stated = f"{source}: counts_per_rev = {counts} (ASSUMED: rippleb's default; give it in --joint FILE)"
    return {key: check_counts(counts, log.encoder, log.index, source, stated), "gear_ratio": GEAR_RATIO_NOTE}
