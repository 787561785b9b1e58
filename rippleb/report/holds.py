"""Where each conclusion holds: the report's claims re-evaluated over swept physics.

Some physics is only bounded by the sources (the share of the transmission error at order
2, the flexspline's compliance varying at twice the wave-generator angle, ...), and a
published conclusion may hinge on it. ``rippleb report DIR --sweep SWEEP ...`` reads the
rows of sensitivity sweeps (``rippleb sweep``, docs/sweeps.md) and re-evaluates, at every
grid value of every swept parameter, each conclusion of the report on ``DIR``'s rows:

* each claim "``first`` leads ``second`` under a condition" (:mod:`rippleb.report.claims`),
  by the same paired test on the sweep's devices (all of them: a sweep is the check, not a
  discovery), two-sided, Holm-corrected over the grid values of that claim, so that at
  each value it reads *leads*, *not separated* or *the other leads*;
* the method of lowest mean under each condition, among the methods the sweep ran;
* each method's rank under each condition among them (its verdict's "where it ranks").

Means are over the sweep's scenarios (those every swept method finished), which may be
fewer than the report's. A boundary lies between two grid values; no finer than the grid
is measured. Any parameter :mod:`rippleb.engine.params` can sweep works: the section is
generic, and a sweep of several parameters is read one parameter at a time, at each
combination of the others' values.

The section is a list of blocks (:func:`holds_blocks`), written as Markdown
(:func:`blocks_markdown`) and as HTML by :mod:`rippleb.report.html_report`, so both pages
say the same things.
"""

from __future__ import annotations

from rippleb.engine.results import swept_columns
from rippleb.printable import markdown_code as code
from rippleb.report.conditions import condition_claims, condition_summary
from rippleb.report.markdown import markdown, plural
from rippleb.report.paired import paired_tests
from rippleb.report.stats import condition_order, method_order, ok_rows, per_seed_mean_over_scenarios, with_condition

TITLE = "Where each conclusion holds"
INTRO = ("Each conclusion above, re-evaluated at every value of each swept parameter of the uncertain "
         "physics, on the sweep's own devices and scenarios: a paired lead by the same Wilcoxon "
         "signed-rank test (two-sided, Holm over the values of one parameter), the lowest mean and each "
         "method's rank among the methods the sweep ran. Between two values of a grid nothing is "
         "measured; a boundary lies somewhere between them.")


def holds_blocks(frame, sweeps) -> list[tuple[str, object]]:
    """The section as blocks ``(kind, content)``: ``h2``/``h3``/``h4``/``p`` (text),
    ``table`` (Markdown) and ``ul`` (a list of sentences).

    Parameters
    ----------
    frame
        The report's rows: its claims are those re-evaluated.
    sweeps
        ``[(name, rows), ...]``: each sweep's name (the directory it was read from) and
        its rows, with at least one swept column.
    """
    if not sweeps:
        return []
    frame = with_condition(frame)
    claims = condition_claims(frame)
    summary = condition_summary(frame)
    leaders = {c: g.iloc[0]["method"] for c, g in summary.dropna(subset=["mean"]).groupby("condition", sort=False)}
    blocks = [("h2", TITLE), ("p", INTRO)]
    covered = set()
    for name, rows in sweeps:
        rows = with_condition(rows)
        ran = ok_rows(rows)
        covered |= {c.key for c in claims if c.key in set(ran["condition"])
                    and {c.first, c.second} <= set(ran["method"])}
        for column in swept_columns(rows.columns):
            others = [c for c in swept_columns(rows.columns) if c != column]
            for fixed, part in (rows.groupby(others, sort=True) if others else [((), rows)]):
                fixed = fixed if isinstance(fixed, tuple) else (fixed,)
                label = "".join(f", {code(c)} = {v:g}" for c, v in zip(others, fixed))
                blocks += _one_parameter(name, column, label, part, claims, leaders)
    missed = [c for c in claims if c.key not in covered]
    if missed:
        blocks.append(("p", "No sweep ran the two methods and the condition of: " + "; ".join(
            f"{code(c.first)} against {code(c.second)} under {code(c.key)}" for c in missed) + "."))
    return blocks


def _one_parameter(name, column, label, rows, claims, leaders) -> list[tuple[str, object]]:
    ok = ok_rows(rows)
    values = sorted(ok[column].dropna().unique())
    methods = method_order(ok["method"].unique())
    conditions = condition_order(ok["condition"].unique())
    head = (f"{code(column)}{label}: sweep {code(name)}, {plural(len(methods), 'method')}, "
            f"{plural(ok['scenario'].nunique(), 'scenario')}, {plural(ok['seed'].nunique(), 'device')}")
    blocks = [("h3", head)]
    if len(values) < 2:
        return blocks + [("p", f"Only one value of {code(column)} has ok rows: nothing to compare.")]
    per_value = {(c, v): _per_device(ok, column, c, v) for c in conditions for v in values}
    table, sentences = [], []
    for claim in claims:
        if claim.key not in conditions or not {claim.first, claim.second} <= set(methods):
            continue
        verdicts = _lead_verdicts(claim, [per_value[(claim.key, v)] for v in values])
        pair = f"{code(claim.first)} against {code(claim.second)} under {code(claim.key)}"
        what = f"{pair} (in this report: {claim.status})"
        table.append([what] + [text for _, text in verdicts])
        sentences.append(_ranges(pair, column, values,
                                 [word for word, _ in verdicts]))
    for condition in conditions:
        lowest = [_lowest(per_value[(condition, v)]) for v in values]
        published = leaders.get(condition)
        what = (f"lowest mean under {code(condition)} among the swept methods"
                + (f" (this report: {code(published)})" if published else ""))
        table.append([what] + [code(m) if m else "n/a" for m in lowest])
        sentences.append(_ranges(f"the lowest mean under {code(condition)}", column, values,
                                 [code(m) if m else "n/a" for m in lowest]))
    blocks += [("table", markdown(table, ["conclusion"] + [f"{v:g}" for v in values])), ("ul", sentences)]
    for condition in conditions:
        ranks = [_ranks(per_value[(condition, v)]) for v in values]
        rows_ = [[code(m)] + [str(r.get(m, "n/a")) for r in ranks] for m in methods]
        blocks += [("h4", f"Each method's rank under {code(condition)} among the {len(methods)} swept methods, "
                          f"by {code(column)}{label}"),
                   ("table", markdown(rows_, ["method"] + [f"{v:g}" for v in values]))]
    return blocks


def _per_device(ok, column, condition, value):
    """Per method and device, the mean error over the scenarios every swept method finished."""
    part = ok[(ok["condition"] == condition) & (ok[column] == value)]
    means, _ = per_seed_mean_over_scenarios(part)
    return means.set_index(["method", "seed"])["value"]


def _lowest(values):
    means = values.groupby(level="method").mean().dropna()
    return min(means.index, key=lambda m: (means[m], m)) if len(means) else None


def _ranks(values) -> dict:
    means = values.groupby(level="method").mean().dropna()
    order = sorted(means.index, key=lambda m: (means[m], m))
    return {m: i + 1 for i, m in enumerate(order)}


def _lead_verdicts(claim, per_value) -> list[tuple[str, str]]:
    """Per grid value: a short word for the ranges (``leads``, ``not separated``, ``reversed``)
    and the cell: verdict, mean difference and devices where ``first`` is lower."""
    pairs = [(v.xs(claim.first, level="method"), v.xs(claim.second, level="method")) for v in per_value]
    out = []
    for test in paired_tests(pairs):
        numbers = f"{test.mean:+.3g} Nm, {test.wins}/{test.n}"
        if test.verdict == "unknown":
            out.append(("no paired test", f"fewer than two devices ({test.n})"))
        elif test.verdict == "separated":
            out.append((f"{code(claim.first)} leads", f"{code(claim.first)} leads ({numbers})"))
        elif test.p < 0.05:     # separated the other way
            out.append((f"{code(claim.second)} leads", f"{code(claim.second)} leads ({numbers})"))
        else:
            out.append(("not separated", f"not separated ({numbers})"))
    return out


def _ranges(what: str, column: str, values, words) -> str:
    """``what``: ``word`` for ``column`` <= a; ``word`` from b to c; ... over runs of equal words."""
    runs, start = [], 0
    for i in range(1, len(values) + 1):
        if i == len(values) or words[i] != words[start]:
            runs.append((start, i - 1))
            start = i
    parts = []
    for a, b in runs:
        if len(runs) == 1:
            where = f"at every value of {code(column)} swept ({values[0]:g} to {values[-1]:g})"
        elif a == b:
            where = f"at {code(column)} = {values[a]:g}"
        elif a == 0:
            where = f"for {code(column)} <= {values[b]:g}"
        elif b == len(values) - 1:
            where = f"for {code(column)} >= {values[a]:g}"
        else:
            where = f"for {code(column)} from {values[a]:g} to {values[b]:g}"
        parts.append(f"{words[a]} {where}")
    return f"{what}: " + "; ".join(parts) + "."


def blocks_markdown(blocks) -> str:
    """The blocks as Markdown."""
    out = []
    for kind, content in blocks:
        if kind in ("h2", "h3", "h4"):
            out += [f"{'#' * int(kind[1])} {content}", ""]
        elif kind == "ul":
            out += [f"- {s}" for s in content] + [""]
        else:
            out += [content, ""]
    return "\n".join(out)
