"""Paired tests that survive heavy tails (rippleb/report/paired.py) and claims made on one
half of the devices and checked on the other (rippleb/report/claims.py)."""

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings, strategies as st

from rippleb.report.claims import DISCOVERY, REPLICATION, claim_family, half, headlines
from rippleb.report.paired import ALPHA, paired_test, paired_tests
from rippleb.signed_rank import holm
from rippleb.report.stats import t_interval


def _series(values, seeds=None):
    return pd.Series(np.asarray(values, float), index=list(seeds if seeds is not None else range(len(values))))


def _values(errors: dict, seeds) -> pd.Series:
    """``{method: [error per seed]}`` as the ``(method, seed)`` Series a claim family reads."""
    index = pd.MultiIndex.from_tuples([(m, s) for m in errors for s in seeds], names=["method", "seed"])
    return pd.Series(np.concatenate([np.asarray(v, float) for v in errors.values()]), index=index)


def test_a_lead_hidden_by_the_device_spread_is_found_by_pairing():
    """Devices differ far more than the methods do: the two 95 % intervals overlap, yet one
    method is lower on every device by 0.05 +- 0.01 Nm."""
    device = np.array([0.3, 0.9, 0.5, 1.4, 0.7, 1.1, 0.4, 0.8] * 2)
    better = _series(device)
    worse = _series(device + 0.05 + 0.001 * np.arange(16) * (-1) ** np.arange(16))
    first, second = t_interval(better), t_interval(worse)
    assert first[0] + first[1] > second[0] - second[1]            # the unpaired intervals overlap
    test = paired_test(better, worse)
    assert test.verdict == "separated" and test.wins == 16 and test.mean == pytest.approx(0.0495)
    assert test.p == pytest.approx(2 / 2 ** 16)                   # exact: all 16 signs the same way
    assert paired_test(worse, better).verdict == "not separated"  # the test has a direction
    assert paired_test(better, worse.iloc[:1]).verdict == "unknown"


def test_a_mean_carried_by_a_few_devices_is_not_a_lead():
    """The issue's case: a mean lead that most devices do not show. Three devices gain
    0.6 Nm, seventeen lose 0.02: the mean difference is positive, but the verdict follows
    the signed-rank test, which sees seventeen of twenty devices the other way."""
    d = np.array([0.6, 0.6, 0.6] + [-0.02] * 17)
    first, second = _series(np.ones(20)), _series(np.ones(20) + d)
    test = paired_test(first, second)
    assert test.mean > 0 and test.wins == 3
    assert test.verdict == "not separated" and not test.toward_first


def test_holm_is_the_step_down_of_bonferroni():
    assert holm([0.01, 0.04, 0.03]) == pytest.approx([0.03, 0.06, 0.06])
    assert holm([0.001, 0.5]) == pytest.approx([0.002, 0.5])
    adjusted = holm([0.2, float("nan"), 0.01])
    assert np.isnan(adjusted[1]) and adjusted[0] == pytest.approx(0.2) and adjusted[2] == pytest.approx(0.02)


@given(st.lists(st.floats(1e-6, 1.0), min_size=1, max_size=12))
def test_holm_never_lowers_a_p_value_and_never_exceeds_bonferroni(pvalues):
    adjusted = holm(pvalues)
    k = len(pvalues)
    for p, a in zip(pvalues, adjusted):
        assert p <= a + 1e-15 and a <= min(1.0, k * p) + 1e-15
    order = np.argsort(pvalues, kind="stable")
    assert all(np.diff(np.asarray(adjusted)[order]) >= -1e-15)   # the order of the p-values is kept


#: Per-device differences with distinct magnitudes, multiples of 1/64 (exact in binary, so
#: adding a device's difficulty to both methods leaves each difference exactly as it was).
differences = st.lists(st.integers(1, 64), min_size=6, max_size=20, unique=True).flatmap(
    lambda mags: st.lists(st.sampled_from([-1, 1]), min_size=len(mags), max_size=len(mags)).map(
        lambda signs: [s * m / 64 for s, m in zip(signs, mags)]))


@settings(max_examples=30, deadline=None)
@given(differences, st.lists(st.integers(0, 256), min_size=20, max_size=20))
def test_the_device_itself_cancels(d, difficulty):
    """Adding any per-device difficulty to both methods changes nothing: the test reads
    only the per-device differences."""
    n = len(d)
    base = _series(np.ones(n))
    plain = paired_test(base, base + _series(d))
    hard = _series(np.asarray(difficulty[:n]) / 64)
    moved = paired_test(base + hard, base + hard + _series(d))
    assert (moved.wins, moved.verdict, moved.p) == (plain.wins, plain.verdict, plain.p)


@settings(max_examples=30, deadline=None)
@given(differences, st.integers(2, 1000))
def test_an_outlier_pushed_further_out_changes_no_verdict(d, factor):
    """Heavy tails: moving the device of largest difference further out in its own
    direction changes no rank, so neither the p-value nor the verdict moves, while the
    mean and its t-interval do."""
    d = np.asarray(d)
    i = int(np.argmax(np.abs(d)))
    pushed = d.copy()
    pushed[i] *= factor
    base = _series(np.ones(len(d)))
    before, after = paired_test(base, base + _series(d)), paired_test(base, base + _series(pushed))
    assert (after.p, after.verdict) == (before.p, before.verdict)
    assert after.mean != before.mean


@settings(max_examples=30, deadline=None)
@given(differences)
def test_swapping_the_methods_keeps_the_two_sided_p_and_turns_the_direction(d):
    base = _series(np.ones(len(d)))
    ab, ba = paired_test(base, base + _series(d)), paired_test(base + _series(d), base)
    assert ab.p == ba.p and ab.wins + ba.wins == len(d)
    if ab.verdict == "separated":
        assert ba.verdict == "not separated"


def test_a_family_is_corrected_together():
    strong = (_series(np.zeros(12)), _series(np.linspace(0.1, 0.2, 12)))
    alone = paired_tests([strong])[0]
    five = paired_tests([strong] * 5)
    assert all(t.claims == 5 for t in five)
    assert five[0].p == pytest.approx(min(1.0, 5 * alone.p))        # equal p-values: Holm = Bonferroni
    assert five[0].half > alone.half                                  # the t-interval at 99 %
    assert "99 % t-interval for 5 claims" in five[0].describe() and "Holm for 5 claims" in five[0].describe()


# --------------------------------------------------------------------------- claims

SEEDS = list(range(20))


def test_the_halves_are_the_even_and_the_odd_seeds():
    assert half(range(7), DISCOVERY) == [0, 2, 4, 6] and half([5, 2, 3], REPLICATION) == [3, 5]


def test_a_claim_true_on_every_device_replicates_and_is_a_headline():
    values = _values({"a": [0.5 + 0.01 * k for k in SEEDS], "b": [0.6 + 0.01 * k for k in SEEDS],
                      "c": [0.9] * 20}, SEEDS)
    claim, = claim_family([("creep", "on `creep`", values)])
    assert (claim.first, claim.second, claim.status) == ("a", "b", "replicated")
    assert claim.discovery.n == 10 and claim.replication.n == 10 and claim.replication.alternative == "greater"
    assert headlines([claim]) == [claim]
    assert claim.sentence().startswith("`a` leads `b` on `creep`: on the 10 discovery devices (even seeds)")
    assert "replicated on the 10 odd seeds" in claim.sentence()


def test_a_claim_the_other_devices_do_not_show_is_no_headline():
    """``a`` leads on the even seeds only: the claim is made there, fails on the odd seeds,
    and is printed as not replicated, never as a headline."""
    a = [0.5 if k % 2 == 0 else 0.7 for k in SEEDS]
    values = _values({"a": [v + 0.001 * k for k, v in enumerate(a)], "b": [0.6 + 0.001 * k for k in SEEDS]}, SEEDS)
    claim, = claim_family([("aged", "under `aged`", values)])
    assert claim.discovery.verdict == "separated" and claim.status == "not replicated"
    assert headlines([claim]) == []
    assert "not replicated on the 10 odd seeds" in claim.sentence() and "No headline" in claim.sentence()
    assert claim.cell().startswith("not replicated: a leads b, lower on 10/10 even seeds")


def test_a_claim_not_made_is_not_checked():
    rng = np.random.default_rng(3)
    noise = rng.normal(0, 0.05, size=(2, 20))
    values = _values({"a": 1 + noise[0], "b": 1 + noise[1]}, SEEDS)
    claim, = claim_family([("creep", "on `creep`", values)])
    assert claim.status == "not separated" and claim.replication is None
    assert "no claim is made" in claim.sentence()


@settings(max_examples=15, deadline=None)
@given(st.lists(st.floats(0.1, 3.0), min_size=30, max_size=30))
def test_what_the_replication_devices_hold_never_changes_the_claim_made(odd):
    """The claim (which pair, and its discovery test) is a function of the even seeds alone:
    the split is fixed before the replication devices are looked at."""
    base = {"a": [0.5 + 0.01 * k for k in SEEDS], "b": [0.55 + 0.012 * k for k in SEEDS],
            "c": [0.8 + 0.01 * k for k in SEEDS]}
    changed = {m: [odd[i * 10 + k // 2] if k % 2 else v for k, v in enumerate(errors)]
               for i, (m, errors) in enumerate(base.items())}
    one, = claim_family([("x", "on `x`", _values(base, SEEDS))])
    two, = claim_family([("x", "on `x`", _values(changed, SEEDS))])
    assert (one.first, one.second, one.discovery) == (two.first, two.second, two.discovery)


def test_a_family_of_claims_shares_its_correction():
    groups = []
    for i, name in enumerate(("creep", "reversal", "load-steps")):
        groups.append((name, f"on `{name}`", _values({"a": [0.5 + 0.01 * k for k in SEEDS],
                                                      "b": [0.6 + 0.01 * k + 0.1 * i for k in SEEDS]}, SEEDS)))
    claims = claim_family(groups)
    assert [c.key for c in claims] == ["creep", "reversal", "load-steps"]
    assert all(c.discovery.claims == 3 and c.replication.claims == 3 for c in claims)
    assert all(c.discovery.p < ALPHA for c in claims)
