"""The paired test every comparison of rippleb reads: Wilcoxon signed-rank, Holm-corrected.

Two methods run on the same devices are compared by the per-device differences of their
errors. Those differences are heavy-tailed (one device may differ by ten times the
typical one), so a verdict follows a distribution-free test of them, not a t-interval: the
Wilcoxon signed-rank test (``scipy.stats.wilcoxon``: its exact null distribution for up to
50 differences without ties or zeros, else scipy's permutation test (up to 13) or normal
approximation). A family of claims is corrected by Holm's step-down method. The report's
claims (:mod:`rippleb.report.paired`) and the tuning rule (:mod:`rippleb.tuning`) both use
these two functions, and nothing else decides a lead.
"""

from __future__ import annotations

import numpy as np

#: The family-wise error level of every decision made with this test.
ALPHA = 0.05


def signed_rank(d, alternative: str = "two-sided") -> tuple[float, bool]:
    """The Wilcoxon signed-rank p-value of the differences ``d`` and their direction.

    Parameters
    ----------
    d
        Per-device differences, positive where the first of the pair is better.
    alternative
        ``two-sided``, or ``greater`` when the direction (``d > 0``) was fixed before.

    Returns
    -------
    p, positive
        The p-value (NaN for fewer than two differences, 1 when every one is zero), and
        whether the signed ranks lean toward ``d > 0`` (the larger rank sum).
    """
    d = np.asarray(d, float)
    nonzero = d[d != 0]
    if len(d) < 2:
        return float("nan"), False
    if len(nonzero) == 0:     # the same on every device: nothing to rank
        return 1.0, False
    from scipy.stats import rankdata, wilcoxon

    ranks = rankdata(np.abs(nonzero))
    positive = bool(ranks[nonzero > 0].sum() > ranks[nonzero < 0].sum())
    return float(wilcoxon(d, alternative=alternative).pvalue), positive


def holm(pvalues) -> list[float]:
    """Holm's step-down adjustment: the ``i``-th smallest of ``k`` p-values times
    ``k - i`` (``i`` from 0), made non-decreasing and capped at 1; NaN stays NaN and does
    not count towards ``k``.

    >>> holm([0.01, 0.04, 0.03])
    [0.03, 0.06, 0.06]
    """
    p = np.asarray(pvalues, float)
    out = np.full(len(p), np.nan)
    valid = np.flatnonzero(np.isfinite(p))
    order = valid[np.argsort(p[valid], kind="stable")]
    k, running = len(order), 0.0
    for i, j in enumerate(order):
        running = max(running, min(1.0, (k - i) * p[j]))
        out[j] = running
    return [float(v) for v in out]
