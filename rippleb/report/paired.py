"""Paired per-device comparisons: the one statistic behind every "leads" in a report.

Every seed is one device that all methods of a run share, so two methods are compared by
the per-device difference of their errors, not by whether their two intervals overlap:
the device's own difficulty, which moves both methods alike, then cancels.

Device-to-device differences are heavy-tailed (one device may differ by ten times the
typical one), and a t-interval over a few tens of them then claims more than a second set
of devices supports. So the verdict of a comparison follows a distribution-free test, the
**Wilcoxon signed-rank test** of the per-device differences (``scipy.stats.wilcoxon``: its
exact null distribution for up to 50 devices without ties, else scipy's permutation or
normal approximation; :mod:`rippleb.signed_rank`, which the tuning rule uses too). A report
makes several claims at once (one per condition, one per scenario of a ranking); the
p-values of one family are corrected by **Holm's** step-down method, so that all of its claims hold together at the 5 % level. Beside the test, the
mean difference and its t-interval describe the size of the lead; that interval is widened
to the Bonferroni level ``1 - 0.05 / k`` for the ``k`` claims of its family (Holm has no
interval of its own), and no verdict is read from it.

:func:`paired_tests` computes a family; every table and sentence of a report that says one
method leads another goes through it (:mod:`rippleb.report.claims`).

Examples
--------
>>> import pandas as pd
>>> a = pd.Series([1.0, 1.1, 0.9, 1.0, 1.2, 0.8, 1.05, 0.95], index=range(8))
>>> b = a + pd.Series([0.10, 0.12, 0.09, 0.11, 0.13, 0.08, 0.105, 0.095], index=range(8))
>>> test, = paired_tests([(a, b)])
>>> test.verdict, test.wins, test.n, round(test.p, 4)
('separated', 8, 8, 0.0078)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rippleb.report.stats import fmt_interval, t_interval
from rippleb.signed_rank import ALPHA, holm, signed_rank
#: The correction for the number of claims of a family, as the report names it.
CORRECTION = "Holm"
TEST = "Wilcoxon signed-rank"


@dataclass(frozen=True)
class PairedTest:
    """How much lower ``first``'s error is than ``second``'s, device by device.

    Attributes
    ----------
    n, wins
        Shared devices, and on how many ``first`` has the lower error.
    median
        Median of ``second - first`` over the shared devices [same unit as the errors].
    mean, half
        Mean of ``second - first`` and the half-width of its t-interval at ``confidence``.
    confidence
        The t-interval's level: ``1 - ALPHA / claims`` (Bonferroni).
    p
        The Wilcoxon signed-rank p-value of the differences, Holm-adjusted for ``claims``
        (1 where no difference is non-zero; NaN for fewer than two devices).
    claims
        The number of claims of the family the test belongs to.
    alternative
        ``two-sided`` (who leads is read from the same devices) or ``greater`` (the
        direction was fixed before, on other devices: a replication).
    toward_first
        True when the signed ranks favour ``first`` (its rank sum of lower errors is the
        larger), the direction a two-sided test separates.
    """

    n: int
    wins: int
    median: float
    mean: float
    half: float
    confidence: float
    p: float
    claims: int
    alternative: str
    toward_first: bool

    @property
    def verdict(self) -> str:
        """``separated`` (the test rejects no lead at ``ALPHA`` after the correction, toward
        ``first``), ``not separated``, or ``unknown`` (fewer than two shared devices)."""
        if self.n < 2 or not np.isfinite(self.p):
            return "unknown"
        return "separated" if self.p < ALPHA and self.toward_first else "not separated"

    def describe(self, digits: int = 3) -> str:
        """``lower on 24/25 devices (median 0.045 Nm; mean 0.047 ± 0.014 Nm, 99 % t-interval
        for 5 claims; Wilcoxon signed-rank p = 3.6e-07, Holm for 5 claims)``."""
        level = f"{100 * self.confidence:.4g} %"
        many = f" for {self.claims} claims" if self.claims > 1 else ""
        sided = ", one-sided" if self.alternative == "greater" else ""
        return (f"lower on {self.wins}/{self.n} devices (median {self.median:.{digits}g} Nm; mean "
                f"{fmt_interval(self.mean, self.half, digits)} Nm, {level} t-interval{many}; {TEST} "
                f"p = {_p_text(self.p)}{sided}{f', {CORRECTION}' + many if many else ''})")


def paired_tests(pairs, alternative: str = "two-sided") -> list[PairedTest]:
    """One family of paired comparisons, corrected together.

    Parameters
    ----------
    pairs
        ``[(first, second), ...]``: two pandas Series of one error per device (indexed by
        seed) per claim; only devices where both have a finite value count.
    alternative
        ``two-sided``, or ``greater`` when each claim's direction (``first`` lower) was
        fixed before looking at these devices.

    Returns
    -------
    list of PairedTest
        In the order of ``pairs``, p-values Holm-adjusted over the family and t-intervals at
        the Bonferroni level.
    """
    diffs = [_differences(first, second) for first, second in pairs]
    claims = max(1, len(diffs))
    confidence = 1.0 - ALPHA / claims
    raw = [signed_rank(d, alternative) for d in diffs]
    adjusted = holm([p for p, _ in raw])
    out = []
    for d, (_, toward), p in zip(diffs, raw, adjusted):
        mean, half, n = t_interval(d, confidence)
        out.append(PairedTest(n=n, wins=int((d > 0).sum()), median=float(np.median(d)) if n else float("nan"),
                              mean=mean, half=half, confidence=confidence, p=p, claims=claims,
                              alternative=alternative, toward_first=toward))
    return out


def paired_test(first, second, alternative: str = "two-sided") -> PairedTest:
    """A family of one claim: :func:`paired_tests` of the single pair."""
    return paired_tests([(first, second)], alternative)[0]


def _differences(first, second) -> np.ndarray:
    both = first.to_frame("a").join(second.to_frame("b"), how="inner").dropna()
    both = both[np.isfinite(both["a"]) & np.isfinite(both["b"])]
    return (both["b"] - both["a"]).to_numpy(float)


def _p_text(p: float) -> str:
    if not np.isfinite(p):
        return "n/a"
    return f"{p:.2g}" if p >= 1e-3 else f"{p:.1e}"

