"""The method x condition summary of a report and its claims, as Markdown.

Per condition, per device the mean error over the scenarios every method finished under
it, then the mean and 95 % t-interval over devices (:func:`condition_summary`); per
condition one claim, that the method of lowest mean leads the second, made on the
discovery devices and checked on the replication devices (:mod:`rippleb.report.claims`).
Rows carry a deployment ``condition`` (:mod:`rippleb.simulator.conditions`); rows without
one are ``same-session``.
"""

from __future__ import annotations

from rippleb.printable import markdown_code as md_code, markdown_text as md_text
from rippleb.report.claims import claim_family, headlines
from rippleb.report.markdown import markdown, plural
from rippleb.report.stats import (condition_order, fmt_interval, method_order, per_seed_mean_over_scenarios,
                                  t_interval, with_condition)


def conditions_of(frame) -> list[str]:
    """The conditions of ``frame``'s rows in :func:`~rippleb.report.stats.condition_order`."""
    return condition_order(with_condition(frame)["condition"].unique())


def by_condition(frame):
    """``(condition, rows)`` per condition of ``frame``, in condition order."""
    frame = with_condition(frame)
    for condition in conditions_of(frame):
        yield condition, frame[frame["condition"] == condition]


def condition_summary(frame, column: str = "rms_error_nm"):
    """Method x condition: per seed, the mean of ``column`` over the scenarios every method
    finished under that condition; then mean and 95 % t-interval over seeds.

    Returns
    -------
    pandas.DataFrame
        Columns ``condition, method, mean, half, n, scenarios`` (the number of scenarios
        averaged), sorted by condition then mean.
    """
    import pandas as pd

    records = []
    for condition, rows in by_condition(frame):
        per_seed, common = per_seed_mean_over_scenarios(rows, column)
        for method, group in per_seed.groupby("method"):
            mean, half, n = t_interval(group["value"])
            records.append({"condition": condition, "method": method, "mean": mean, "half": half,
                            "n": n, "scenarios": len(common)})
    table = pd.DataFrame(records, columns=["condition", "method", "mean", "half", "n", "scenarios"])
    if table.empty:
        return table
    rank = {c: i for i, c in enumerate(condition_order(table["condition"].unique()))}
    table = table.assign(_c=table["condition"].map(rank)).sort_values(["_c", "mean", "method"])
    return table.drop(columns="_c").reset_index(drop=True)


def condition_summary_markdown(frame, column: str = "rms_error_nm") -> str:
    """The method x condition table: one row per method, one column per condition."""
    table = condition_summary(frame, column)
    if table.empty:
        return "(no ok rows)"
    conditions = condition_order(table["condition"].unique())
    cells = {(r.condition, r.method): fmt_interval(r.mean, r.half) for r in table.itertuples()}
    worst = table.dropna(subset=["mean"]).sort_values("mean").groupby("method").last()
    rows = [[md_text(m)] + [cells.get((c, m), "n/a") for c in conditions]
            + ([f"{fmt_interval(worst.loc[m, 'mean'], worst.loc[m, 'half'])} ({md_text(worst.loc[m, 'condition'])})"
                if m in worst.index else "n/a"] if len(conditions) > 1 else [])
            for m in method_order(table["method"].unique())]
    counts = table.groupby("condition")["scenarios"].first()
    heads = [f"{md_text(c)} ({plural(int(counts[c]), 'scenario')})" for c in conditions]
    return markdown(rows, ["method"] + heads + (["worst case over the conditions"] if len(conditions) > 1 else []))


def condition_claims(frame, column: str = "rms_error_nm"):
    """One claim per condition: per device the mean ``column`` over the scenarios every method
    finished under it (as in :func:`condition_summary`), one family
    (:func:`rippleb.report.claims.claim_family`)."""
    groups = []
    for condition, rows in by_condition(frame):
        per_seed, _ = per_seed_mean_over_scenarios(rows, column)
        groups.append((condition, f"under {md_code(condition)}", per_seed.set_index(["method", "seed"])["value"]))
    return claim_family(groups)


def condition_headline(frame, column: str = "rms_error_nm") -> list[str]:
    """Per condition, the claim that the method of lowest mean ``column`` on the discovery
    devices leads the second, with its replication; then whether the method of lowest mean
    over every device changes between conditions. Every number from the rows."""
    table = condition_summary(frame, column)
    if table.empty:
        return []
    scenarios = table.groupby("condition")["scenarios"].first()
    out = []
    for claim in condition_claims(frame, column):
        out.append(f"Under {md_code(claim.key)}, on the discovery devices, {md_code(claim.first)} has the lowest mean "
                   f"`{column}` over the {plural(int(scenarios[claim.key]), 'scenario')} every method "
                   f"finished, ahead of {md_code(claim.second)} ({claim.means_text()} Nm). {claim.sentence()}")
    leaders = {c: g.dropna(subset=["mean"]).iloc[0]["method"] for c, g in table.groupby("condition", sort=False)
               if g["mean"].notna().any()}
    if len(set(leaders.values())) > 1:
        out.append("Over every device, the lowest mean depends on the condition: " +
                   ", ".join(f"{md_code(m)} under {md_code(c)}" for c, m in leaders.items()) + ".")
    elif len(leaders) > 1:
        out.append(f"Over every device, {md_code(next(iter(leaders.values())))} has the lowest mean under every "
                   f"condition of this run (whether it leads is said per condition above).")
    return out


def headline_lines(frame, column: str = "rms_error_nm") -> list[str]:
    """The report's headlines: the condition claims that replicated, one line each, then
    the claims that are no headline and why; every number from the rows."""
    claims = condition_claims(frame, column)
    made = headlines(claims)
    out = [f"{md_code(c.first)} leads {md_code(c.second)} under {md_code(c.key)}: lower by a median of {c.discovery.median:.3g} Nm "
           f"per device, on {c.discovery.wins}/{c.discovery.n} discovery and {c.replication.wins}/"
           f"{c.replication.n} replication devices." for c in made]
    if not made:
        out.append("No claim of who leads under a condition replicated, so there is no headline." if claims
                   else "No claim of who leads could be made (fewer than two methods with ok rows on the "
                        "discovery devices, the even seeds).")
    others = [c for c in claims if not c.headline]
    if others:
        out.append("No headline: " + "; ".join(f"{md_code(c.first)} against {md_code(c.second)} under {md_code(c.key)} ({c.status})"
                                              for c in others) + ".")
    return out

