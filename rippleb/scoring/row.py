"""Scoring one row: the one place where what a method sent becomes a row's columns.

The scheduler of a run (:mod:`rippleb.engine.scheduler`), :func:`rippleb.engine.runner.evaluate`
and the tuner (:mod:`rippleb.engine.tuner`) all score through :func:`score_row`, so an
estimate that cannot stand as an ``ok`` row is ``invalid`` on every path, with the same
message, and the timing columns come from the same ticks.
"""

from __future__ import annotations

import numpy as np

from rippleb.scoring import metrics, rebuilt, truthfree
from rippleb.scoring.metrics import Truth, tick_stats
from rippleb.scoring.scorable import MEASURED, NO_REFERENCE, NO_REFERENCE_MESSAGE, implausible


#: The least time one ``step`` can take by the harness's clock [ns]: a call of a Python method
#: and two readings of the clock take more (a step that returns at once: 100 ns at least,
#: 191 ns median over 20 000 ticks, on the 2-core machine of docs/robustness.md section 11).
#: A method that stops its clock or rewrites its tick times claims less (issue 41: 0 us
#: against 502 us honestly timed).
MIN_TICK_NS = 20


def score_row(arrays: dict, truth: Truth, n_samples: int, n_ticks: int, method_s: float | None = None) -> dict:
    """The columns of a row whose method ran to the end: ``status`` (``ok``,
    :data:`~rippleb.scoring.scorable.NO_REFERENCE` or ``invalid``), ``message`` where it is
    not ``ok``, ``n_samples``, the scores (:func:`score_or_invalid`) and, for a measured row,
    the timing columns (:func:`~rippleb.scoring.metrics.tick_stats`).

    ``arrays`` holds what the row sent: ``estimate`` and ``ticks`` (checked here by
    :func:`check_estimate`, whatever the row claimed); ``method_s`` the seconds its
    method's part took, measured outside its process (None in a process of one's own), which
    the tick times must agree with (:func:`check_ticks`).
    """
    checked = check_estimate(arrays, n_samples, n_ticks)
    if isinstance(checked, str):
        return {"status": "invalid", "message": checked}
    estimate, ticks = checked
    fields = {"status": "ok", "n_samples": n_samples, **score_or_invalid(estimate, truth)}
    if fields["status"] in MEASURED:
        why = check_ticks(ticks, method_s)
        if why:
            return {"status": "invalid", "message": why}
        fields.update(tick_stats(ticks, n_samples, method_s))
    return fields


def check_ticks(ticks: np.ndarray, method_s: float | None) -> str:
    """Why the tick times a row sent cannot be its steps' times, or ''.

    They come from the harness's clock inside the method's process, which the method can
    stop or rewrite; they must each be a time a step can take (:data:`MIN_TICK_NS`), and
    all together no more than ``method_s``, its part of the row as measured outside its
    process (None: measured in a process of one's own, nothing to compare with).
    """
    if not len(ticks):
        return ""
    shortest = int(np.min(ticks))
    if shortest <= 0:
        return "its tick times are not times: a step took no time by the clock in its process"
    if shortest < MIN_TICK_NS:
        return (f"a step took {shortest} ns by the clock in its process, less than any call of a Python method "
                f"takes ({MIN_TICK_NS} ns): its clock does not measure its work")
    total_s = float(np.sum(ticks, dtype=np.float64)) / 1e9
    if method_s is not None and total_s > method_s:
        return (f"its steps took {total_s:.4g} s by the clock in its process, more than the {method_s:.4g} s "
                f"its whole part of the row took, measured outside it")
    return ""


def check_estimate(arrays: dict, n_samples: int, n_ticks: int) -> tuple[np.ndarray, np.ndarray] | str:
    """The estimate and ticks a row sent, or why they cannot be scored (one line).

    The runner re-checks in its own process what the streaming loop checked in the
    row's: a row that claims ``ok`` with a wrong-length or non-finite estimate is
    ``invalid``, whatever it says.
    """
    estimate, ticks = arrays.get("estimate"), arrays.get("ticks")
    if estimate is None or ticks is None:
        return "the row sent no estimate"
    if estimate.dtype != np.float64 or estimate.shape != (n_samples,):
        return f"estimate of shape {estimate.shape} dtype {estimate.dtype}, expected {n_samples} float64 values"
    if not np.isfinite(estimate).all():
        return "estimate holds NaN/inf values"
    if ticks.dtype.kind not in "iu" or ticks.shape != (n_ticks,):
        return f"tick times of shape {ticks.shape}, expected {n_ticks}"
    return estimate, ticks


def score_or_invalid(estimate: np.ndarray, truth: Truth) -> dict:
    """The accuracy columns of an estimate (:func:`rippleb.scoring.metrics.score`), its truth-free
    columns (:func:`rippleb.scoring.truthfree.truth_free_scores`) and, on a log with a model
    reference, its error against the rebuilt torque (:func:`rippleb.scoring.rebuilt.reference_scores`);
    or, when they cannot stand as an ``ok`` row, ``{"status": "invalid", "message": why}``.

    Every accuracy column must be finite or NaN (NaN: not defined for this log, e.g. no
    ``torque_true`` in a recording), and the errors against each reference the log has must
    be finite. A finite estimate can still overflow them (a strain scaled by 1e306 gave
    ``rms_error_ref_nm = inf``); the overflow itself is expected here, hence no warning.
    A recorded log's row is ``invalid`` too when its estimate is beyond the joint's range,
    and :data:`~rippleb.scoring.scorable.NO_REFERENCE` when the log has no reference (:mod:`rippleb.scoring.scorable`).
    """
    why = implausible(estimate, truth.torque_limit)
    if why:
        return {"status": "invalid", "message": why}
    with np.errstate(over="ignore", invalid="ignore"):
        scores = {**metrics.score(estimate, truth), **truthfree.truth_free_scores(estimate, truth),
                  **rebuilt.reference_scores(estimate, truth)}
    needed = {c for c, ref in (("rms_error_nm", truth.torque_true), ("max_error_nm", truth.torque_true),
                                ("rms_error_ref_nm", truth.torque_ref), ("max_error_ref_nm", truth.torque_ref))
              if ref is not None}
    bad = [f"{c} = {v}" for c, v in scores.items() if np.isinf(v) or (c in needed and not np.isfinite(v))]
    if bad:
        return {"status": "invalid", "message": f"its scores are not finite ({', '.join(bad)}): the estimate "
                                                f"or the log is beyond what float64 can score"}
    if truth.torque_true is None and truth.torque_ref is None:
        return {**scores, "status": NO_REFERENCE, "message": NO_REFERENCE_MESSAGE}
    return scores
