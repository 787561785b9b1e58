"""The per-method verdicts and the worst-case column of the method x condition table."""

import itertools

import pandas as pd

from rippleb.report.tables import condition_summary_markdown
from rippleb.report.verdicts import MECHANISMS, method_verdicts


def _frame(errors: dict) -> pd.DataFrame:
    """``{(method, condition): error}`` on two scenarios and three seeds (seed adds 0.01 k)."""
    rows = [{"method": m, "condition": c, "scenario": s, "seed": k, "status": "ok",
             "rms_error_nm": e + 0.01 * k}
            for (m, c), e in errors.items() for s, k in itertools.product(("a", "b"), range(3))]
    return pd.DataFrame(rows)


FRAME = _frame({("angle-adaptive", "same-session"): 0.4, ("angle-adaptive", "realistic"): 0.6,
                ("raw", "same-session"): 1.2, ("raw", "realistic"): 1.3,
                ("my-plugin", "same-session"): 0.9, ("my-plugin", "realistic"): 0.5})


def test_verdicts_say_where_each_method_wins_breaks_and_what_the_mismatch_costs():
    lines = {line.split("`")[1]: line for line in method_verdicts(FRAME)}
    assert lines["angle-adaptive"].startswith("`angle-adaptive`: lowest mean under `same-session`; best under "
                                              "`same-session`")
    assert "worst under `realistic`" in lines["angle-adaptive"]
    assert "changes its error by +0.2 Nm (+49%)" in lines["angle-adaptive"]
    assert lines["angle-adaptive"].endswith(f"Why: {MECHANISMS['angle-adaptive']}.")
    assert "lowest mean under `realistic`" in lines["my-plugin"] and "-0.4 Nm (-44%)" in lines["my-plugin"]
    assert "Why" not in lines["my-plugin"]  # a plugin's mechanism is not rippleb's to state
    assert "rank 3 of 3" in lines["raw"]


def test_every_builtin_method_has_a_mechanism():
    from rippleb.registry import Registry

    assert set(Registry.discover().names("builtin")) == set(MECHANISMS)


def test_the_worst_case_column_names_its_condition():
    table = condition_summary_markdown(FRAME)
    assert "worst case over the conditions" in table.splitlines()[0]
    row = next(line for line in table.splitlines() if line.startswith("| angle-adaptive "))
    assert row.rstrip(" |").endswith("(realistic)")
    one = condition_summary_markdown(FRAME[FRAME["condition"] == "same-session"])
    assert "worst case" not in one  # one condition: nothing to take the worst of


def test_a_run_of_one_condition_says_where_each_method_ranks_and_why():
    one = FRAME[FRAME["condition"] == "same-session"]
    lines = {line.split("`")[1]: line for line in method_verdicts(one)}
    assert lines["angle-adaptive"].startswith("`angle-adaptive`: lowest mean under `same-session`; rank 1 of 3 "
                                              "under `same-session`")
    assert "rank 3 of 3 under `same-session`" in lines["raw"] and "worst under" not in lines["raw"]
    assert lines["raw"].endswith(f"Why: {MECHANISMS['raw']}.")
