"""The statistics every table and figure shares: intervals over seeds, orderings, conditions.

One home for them, so that :mod:`rippleb.report.tables`, :mod:`rippleb.report.figures` and
:mod:`rippleb.report.html_report` compute a cell the same way and none imports another.
"""

from __future__ import annotations

import functools

import numpy as np

CONFIDENCE = 0.95

#: The paper's scenario, listed first in every table.
PAPER_SCENARIO = "paper-quintic"

#: The order methods appear in (baselines, the paper's comparison, then the alternatives).
METHOD_ORDER = ("raw", "lowpass", "current-based", "order-tracking", "order-tracking-no-deadzone",
                "order-tracking-no-backprop", "switched-notch", "kalman-ripple", "angle-adaptive",
                "angle-adaptive-frozen", "gear-aware", "gear-keeping", "spatial-filter", "fourier-lms",
                "periodic-dob", "gain-tuned")


def t_interval(values, confidence: float = CONFIDENCE) -> tuple[float, float, int]:
    """Mean and half-width of the Student-t confidence interval of the mean.

    ``mean +- t_{(1+c)/2, n-1} s / sqrt(n)`` with ``s`` the sample standard deviation
    (``ddof=1``), over the finite values only. Seeds are independent devices, so the t
    interval is the textbook choice for the mean over a few tens of them.

    Returns
    -------
    mean, half_width, n
        ``half_width`` is NaN for fewer than two values, ``mean`` NaN for none.
    """
    x = np.asarray(values, float)
    x = x[np.isfinite(x)]
    n = len(x)
    if n == 0:
        return float("nan"), float("nan"), 0
    mean = float(np.mean(x))
    if n < 2:
        return mean, float("nan"), n
    half = float(t_quantile(0.5 + confidence / 2.0, n - 1) * np.std(x, ddof=1) / np.sqrt(n))
    return mean, half, n


@functools.lru_cache(maxsize=None)
def t_quantile(p: float, dof: int) -> float:
    """The ``p`` quantile of Student's t with ``dof`` degrees of freedom.

    ``scipy.special.stdtrit``, the function ``scipy.stats.t.ppf`` evaluates (same
    value), without importing ``scipy.stats`` (a second per process) or the
    distribution machinery's per-call overhead; cached because a report asks for the same
    few degrees of freedom thousands of times.
    """
    from scipy.special import stdtrit

    return float(stdtrit(dof, p))


def fmt_interval(mean: float, half: float, digits: int = 3) -> str:
    """``mean ± half`` in ``digits`` significant digits; ``n/a`` for a missing mean."""
    if not np.isfinite(mean):
        return "n/a"
    if not np.isfinite(half):
        return f"{mean:.{digits}g}"
    if half <= 1e-12 * max(1.0, abs(mean)):  # equal values: rounding noise, not spread
        half = 0.0
    return f"{mean:.{digits}g} ± {half:.2g}"


def ok_rows(frame):
    """The rows with status ok."""
    return frame[frame["status"] == "ok"]


def measured_rows(frame):
    """The rows whose method ran to the end on a log it may be scored on
    (:data:`rippleb.scoring.scorable.MEASURED`: ``ok``, and ``no-reference`` rows of a recording
    without a reference, still ranked by their truth-free scores)."""
    from rippleb.scoring.scorable import MEASURED

    return frame[frame["status"].isin(MEASURED)]


def with_condition(frame):
    """``frame`` with a ``condition`` column: rows of a run made before conditions existed
    were all scored in the calibration session, i.e. ``same-session``."""
    from rippleb.simulator.conditions import DEFAULT_CONDITION

    if "condition" in frame:
        return frame.assign(condition=frame["condition"].fillna(DEFAULT_CONDITION).astype(str))
    return frame.assign(condition=DEFAULT_CONDITION)


def interval_frame(frame, column: str, by=("method", "scenario")):
    """Per group of ``by``: ``mean``, ``half`` (95 % half-width) and ``n`` of ``column``
    over the rows with status ok."""
    import pandas as pd

    by = list(by)
    records = []
    for key, group in ok_rows(frame).groupby(by, sort=False):
        mean, half, n = t_interval(group[column])
        records.append({**dict(zip(by, key)), "mean": mean, "half": half, "n": n})
    return pd.DataFrame(records, columns=by + ["mean", "half", "n"])


def per_seed_mean_over_scenarios(frame, column: str = "rms_error_nm"):
    """Per method and seed, the mean of ``column`` over the scenarios that every method
    finished ok on (so no method is favoured by missing its hardest scenario).

    Returns
    -------
    pandas.DataFrame
        Columns ``method``, ``seed``, ``value``; and the list of common scenarios.
    """
    ok = ok_rows(frame)
    methods = ok["method"].unique()
    common = set.intersection(*(set(ok.loc[ok["method"] == m, "scenario"]) for m in methods)) \
        if len(methods) else set()
    ok = ok[ok["scenario"].isin(common)]
    means = ok.groupby(["method", "seed"])[column].mean().rename("value").reset_index()
    return means, scenario_order(common)


def method_order(names) -> list[str]:
    """Built-in methods in :data:`METHOD_ORDER`, then any other (plugins) alphabetically;
    a method's variants (``order-tracking[q=20]``, :mod:`rippleb.variants`) right after it,
    numbers in their labels compared as numbers (``q=30`` before ``q=100``)."""
    return sorted(set(names), key=_method_key)


def _method_key(label: str) -> tuple:
    import re

    base = label.partition("[")[0]
    rank = METHOD_ORDER.index(base) if base in METHOD_ORDER else len(METHOD_ORDER)
    natural = tuple((0, float(part), "") if re.fullmatch(r"\d+(\.\d*)?", part) else (1, 0.0, part)
                    for part in re.split(r"(\d+(?:\.\d*)?)", label) if part)
    return rank, base, label != base, natural


def scenario_order(names) -> list[str]:
    """The paper's scenario first, then the others alphabetically."""
    names = set(names)
    return [s for s in (PAPER_SCENARIO,) if s in names] + sorted(names - {PAPER_SCENARIO})


def condition_order(names) -> list[str]:
    """The conditions in the order of :data:`rippleb.simulator.conditions.CONDITIONS` (least to most
    changed since calibration), then any unknown name alphabetically."""
    from rippleb.simulator.conditions import CONDITIONS

    names = set(names)
    return [c for c in CONDITIONS if c in names] + sorted(names - set(CONDITIONS))
