"""A report's claims, each made on one half of the devices and checked on the other.

A claim is "``first`` leads ``second``" in one place (under a condition, on a scenario):
the two methods of lowest mean error there. It is **made** on the *discovery* devices, the
even seeds of the run, by the two-sided paired test of :mod:`rippleb.report.paired`
(Wilcoxon signed-rank, Holm over the claims of its family), and **checked** on the
*replication* devices, the odd seeds, which took no part in choosing it: there the
direction is fixed, so the same test is one-sided, Holm-corrected over the claims that
were made. The split is a rule on the seed numbers alone, fixed before any result was
seen; in a sealed run the seeds are indices whose devices are drawn from the secret salt,
so the two halves are two disjoint sets of devices nobody developed against.

A claim that did not replicate is no headline: the report still prints it, says that it
did not replicate, and leaves it out of the headlines (:func:`headlines`).

Examples
--------
>>> import pandas as pd
>>> seeds = range(20)
>>> values = pd.Series([0.5 + 0.01 * k for k in seeds] + [0.6 + 0.01 * k + 0.001 * (k % 3) for k in seeds],
...                    index=pd.MultiIndex.from_product([["a", "b"], seeds], names=["method", "seed"]))
>>> claim, = claim_family([("creep", "on `creep`", values)])
>>> claim.first, claim.second, claim.status
('a', 'b', 'replicated')
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rippleb.printable import markdown_code as md_code, markdown_text as md_text
from rippleb.report.paired import CORRECTION, PairedTest, paired_tests
from rippleb.report.stats import fmt_interval, t_interval

#: The halves of a run's devices, by the parity of the seed: (name, remainder of seed % 2).
DISCOVERY, REPLICATION = ("even seeds", 0), ("odd seeds", 1)


def half(seeds, which) -> list:
    """The seeds of one half (:data:`DISCOVERY` or :data:`REPLICATION`), in order."""
    return sorted(int(s) for s in seeds if int(s) % 2 == which[1])


@dataclass(frozen=True)
class Claim:
    """"``first`` leads ``second`` ``where``": made on the discovery devices, checked on the
    replication devices.

    Attributes
    ----------
    key
        What the claim is about: the condition or scenario name of its group.
    where
        The place in words, e.g. ``under `same-session```.
    first, second
        The methods of lowest and second-lowest mean on the discovery devices.
    means
        ``((mean, half), (mean, half))`` of ``first`` and ``second`` on the discovery
        devices (95 % t-interval).
    discovery
        The two-sided paired test on the discovery devices (Holm over the family).
    replication
        The one-sided paired test on the replication devices (Holm over the claims made),
        or None when the claim was not made (not separated on the discovery devices).
    """

    key: str
    where: str
    first: str
    second: str
    means: tuple
    discovery: PairedTest
    replication: PairedTest | None

    @property
    def status(self) -> str:
        """``replicated``, ``not replicated``, ``not separated`` (on the discovery devices), or
        ``unknown`` (fewer than two discovery devices)."""
        if self.discovery.verdict == "unknown":
            return "unknown"
        if self.discovery.verdict != "separated":
            return "not separated"
        return "replicated" if self.replication.verdict == "separated" else "not replicated"

    @property
    def headline(self) -> bool:
        """Only a replicated claim is a headline."""
        return self.status == "replicated"

    def sentence(self) -> str:
        """The claim in full: who leads where, both tests, and what it is."""
        a, b, d = md_code(self.first), md_code(self.second), self.discovery
        on = f"on the {d.n} discovery devices ({DISCOVERY[0]})"
        if self.status == "unknown":
            return (f"{a} has the lowest mean {self.where} ahead of {b}; fewer than two discovery "
                    f"devices ({DISCOVERY[0]}) give no paired test, so no claim is made.")
        if self.status == "not separated":
            return (f"{a} and {b} are not separated {self.where}: {on}, {a} is {d.describe()}; no "
                    f"claim is made.")
        r = self.replication
        made = f"{a} leads {b} {self.where}: {on}, {a} is {d.describe()}"
        if self.status == "replicated":
            return f"{made}; replicated on the {r.n} {REPLICATION[0]}: {r.describe()}."
        return (f"{made}; not replicated on the {r.n} {REPLICATION[0]}: {r.describe()}. No "
                f"headline.")

    def cell(self) -> str:
        """The claim in one table cell: its status, who, and the devices and p-values."""
        d, r = self.discovery, self.replication
        first = (f"{md_text(self.first)} lower than {md_text(self.second)} on {d.wins}/{d.n} {DISCOVERY[0]} "
                 f"(p = {_p(d)})")
        if self.status in ("unknown", "not separated"):
            return f"{self.status}: {first}"
        return (f"{self.status}: {md_text(self.first)} leads {md_text(self.second)}, lower on {d.wins}/{d.n} {DISCOVERY[0]} "
                f"(p = {_p(d)}) and {r.wins}/{r.n} {REPLICATION[0]} (one-sided p = {_p(r)})")

    def means_text(self) -> str:
        """``0.466 ± 0.034 against 0.513 ± 0.033``: the two discovery means."""
        return " against ".join(fmt_interval(m, h) for m, h in self.means)


def _p(test: PairedTest) -> str:
    p = test.p
    text = "n/a" if not np.isfinite(p) else (f"{p:.2g}" if p >= 1e-3 else f"{p:.1e}")
    return text + (f", {CORRECTION} for {test.claims}" if test.claims > 1 else "")


def claim_family(groups) -> list[Claim]:
    """The claims of one family, corrected together.

    Parameters
    ----------
    groups
        ``[(key, where, values), ...]``: ``key`` names the group (a condition, a scenario),
        ``where`` says it in Markdown (``under `aged```, names written by
        :func:`~rippleb.printable.markdown_code`), ``values`` is a pandas Series of one error per method and
        device, indexed by ``(method, seed)``. A group with fewer than two methods makes no
        claim and is left out.

    Returns
    -------
    list of Claim
        One per group with at least two methods, in the order of ``groups``.
    """
    made = []
    for key, where, values in groups:
        seeds = values.index.get_level_values("seed")
        found = values[np.isin(seeds, half(seeds.unique(), DISCOVERY))]
        means = found.groupby(level="method").mean().dropna()
        if len(means) < 2:
            continue
        first, second = sorted(means.index, key=lambda m: (means[m], m))[:2]
        made.append((key, where, values, first, second, found))
    discovered = paired_tests([(_of(found, a), _of(found, b)) for *_, a, b, found in made])
    kept = [i for i, test in enumerate(discovered) if test.verdict == "separated"]
    checked = dict(zip(kept, paired_tests([_replication_pair(made[i]) for i in kept], "greater")))
    claims = []
    for i, ((key, where, _, a, b, found), test) in enumerate(zip(made, discovered)):
        means = tuple(t_interval(_of(found, m))[:2] for m in (a, b))
        claims.append(Claim(key=key, where=where, first=a, second=b, means=means, discovery=test,
                            replication=checked.get(i)))
    return claims


def _of(values, method):
    """One method's values, indexed by seed."""
    return values.xs(method, level="method")


def _replication_pair(made):
    _, _, values, first, second, _ = made
    seeds = values.index.get_level_values("seed")
    other = values[np.isin(seeds, half(seeds.unique(), REPLICATION))]
    return _of(other, first), _of(other, second)


def headlines(claims) -> list[Claim]:
    """The claims that replicated: the only ones a report may headline."""
    return [c for c in claims if c.headline]


def split_sentence(seeds) -> str:
    """How the run's devices were split, in one sentence."""
    found, other = half(seeds, DISCOVERY), half(seeds, REPLICATION)
    return (f"Each claim below is made on the {len(found)} {DISCOVERY[0]} (the discovery devices) and "
            f"checked on the {len(other)} {REPLICATION[0]} (the replication devices), a split fixed by the "
            f"seed numbers before any result was seen: a {_TEST_WORDS}")


_TEST_WORDS = ("claim is made when the two-sided Wilcoxon signed-rank test of the per-device "
               "differences separates the two methods at 5 % after Holm's correction over the claims "
               "of its list, and it replicates when the one-sided test in the same direction does so "
               "on the replication devices (Holm over the claims made). Only a replicated claim is a "
               "headline. The mean difference and its t-interval (at the Bonferroni level for the "
               "claims of the list) are given beside, as the size of the lead; no verdict is read "
               "from them, because device-to-device differences are heavy-tailed.")
