"""Paired per-device comparisons: the statistic behind every "leads" in a report.

Every seed is one device that all methods of a run share, so two methods are compared by
the per-device difference of their errors, not by whether their two intervals overlap:
the device's own difficulty, which moves both methods alike, then cancels. A lead is
claimed when the t interval of the mean difference excludes zero. A report makes several
such claims (one per scenario of a ranking, one per condition of a summary); each interval
is widened to the Bonferroni level ``1 - 0.05 / k`` for the ``k`` claims of its table, so
that all of them hold together with 95 % confidence.

Examples
--------
>>> import pandas as pd
>>> a = pd.Series([1.0, 1.1, 0.9, 1.0], index=[0, 1, 2, 3])
>>> b = a + pd.Series([0.10, 0.12, 0.09, 0.11], index=[0, 1, 2, 3])
>>> lead = paired_lead(a, b, claims=1)
>>> lead.verdict, lead.wins, lead.n
('separated', 4, 4)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rippleb.report.stats import CONFIDENCE, fmt_interval, t_interval


@dataclass(frozen=True)
class PairedLead:
    """How much lower ``first``'s error is than ``second``'s, device by device.

    Attributes
    ----------
    mean, half
        Mean of ``second - first`` over the shared devices [Nm] and its interval's
        half-width at ``confidence``.
    n, wins
        Shared devices, and on how many ``first`` has the lower error.
    confidence
        The interval's level after the correction for ``claims``.
    claims
        How many claims the interval is corrected for (Bonferroni).
    """

    mean: float
    half: float
    n: int
    wins: int
    confidence: float
    claims: int

    @property
    def verdict(self) -> str:
        """``separated`` (the interval excludes 0, first lower), ``not separated``, or
        ``unknown`` (fewer than two shared devices)."""
        if self.n < 2 or not np.isfinite(self.half):
            return "unknown"
        return "separated" if self.mean - self.half > 0 else "not separated"

    def describe(self, digits: int = 3) -> str:
        """``0.073 ± 0.02 Nm lower on 10/10 devices (paired, 99 % interval for 5 claims)``."""
        level = f"{100 * self.confidence:.4g} %"
        corrected = f" for {self.claims} claims" if self.claims > 1 else ""
        return (f"{fmt_interval(self.mean, self.half, digits)} Nm lower on {self.wins}/{self.n} devices "
                f"(paired, {level} interval{corrected})")


def paired_lead(first, second, claims: int = 1) -> PairedLead:
    """The paired lead of ``first`` over ``second``: two pandas Series of one error per
    device (indexed by seed); only devices both have a finite value for count."""
    both = first.to_frame("a").join(second.to_frame("b"), how="inner").dropna()
    both = both[np.isfinite(both["a"]) & np.isfinite(both["b"])]
    diff = both["b"] - both["a"]
    confidence = 1.0 - (1.0 - CONFIDENCE) / max(1, claims)
    mean, half, n = t_interval(diff, confidence)
    return PairedLead(mean=mean, half=half, n=n, wins=int((diff > 0).sum()), confidence=confidence,
                      claims=max(1, claims))


def lead_text(first: str, second: str, lead: PairedLead) -> str:
    """The sentence a report prints for a paired lead of method ``first`` over ``second``."""
    if lead.verdict == "unknown":
        return f"{first} leads {second}; fewer than two shared devices give no paired interval"
    if lead.verdict == "separated":
        return f"{first} leads {second} by {lead.describe()}"
    return (f"{first} and {second} are not separated: {first} is {lead.describe()}, "
            f"an interval that includes 0")
