"""The tables of a recorded log (``rippleb run --log``): ranked by what the log can score.

A recording has no ``torque_true`` and often no ``torque_ref``. Its rows are ranked by the
best score they hold (:func:`ranking_column`): the error against ``torque_true`` if any row
has one; with a model reference, the error against the torque rebuilt from the strain
(``rms_error_rebuilt_nm``, :mod:`rippleb.scoring.rebuilt`: the model lacks the gear's own torque,
and the error against it rewards erasing that); with a transducer, the error against it;
else the truth-free :data:`TRUTH_FREE_RANKING` (``rippleb/scoring/truthfree.py``). Every other
score is shown beside it with its own rank, and how far the ranking agreed with the truth
on the panel's nearest joint (:mod:`rippleb.report.agreement`). One log is one device: no
intervals. Every number comes from the rows, and from the panel's record for that sentence.
"""

from __future__ import annotations

import numpy as np

from rippleb.printable import escaped, markdown_code, markdown_text
from rippleb.report.markdown import first_line, markdown, one_line, plural
from rippleb.report.stats import measured_rows, method_order, scenario_order
from rippleb.scoring.scorable import MEASURED
from rippleb.report.tables import failed_markdown, is_recorded, summary_text, timing_cells

#: The truth-free column a log without any reference is ranked by: the one whose ranking
#: agreed best with the true ranking on simulated logs of every condition (docs/metrics.md,
#: "How well the truth-free rankings agree with the truth").
TRUTH_FREE_RANKING = "ripple_wg_nm"

#: Every column a recorded log's table shows: (header, unit).
RECORDED_COLUMNS = {
    "rms_error_nm": ("RMS error against torque_true", "Nm"),
    "rms_error_rebuilt_nm": ("RMS error against the torque rebuilt from the strain", "Nm"),
    "rms_error_ref_nm": ("RMS error against torque_ref", "Nm"),
    "ripple_wg_nm": ("ripple left at WG orders 2, 4, 8", "Nm"),
    "rest_std_nm": ("spread at rest", "Nm"),
    "strain_delay_ms": ("delay behind the strain", "ms"),
}

#: What the truth-free columns cannot tell; no number here, so nothing in it can go stale.
TRUTH_FREE_CAVEATS = [
    "`rms_error_rebuilt_nm` (a model reference) is the error against the calibrated strain minus a map of "
    "the gauges' ripple (orders 1-8 of the encoder angle, affine in the load) fitted on this log where the "
    "motor turns slowly, beside an inertial model of the gear's own torque, which stays in it: an error "
    "every strain-based estimate shares with the strain (the gauges' gain, hysteresis, drift, noise) is "
    "not in it, and a ripple that changes with speed counts as torque (docs/metrics.md).",
    "`ripple_wg_nm` is whatever the estimate holds at orders 2, 4 and 8 of the encoder angle while "
    "the joint turns: a real torque at those orders (a load that repeats with the motor angle) "
    "counts as ripple, and an estimate that is wrong in any other way (gain, offset, drift, "
    "noise at other orders) is not seen.",
    "`rest_std_nm` is the estimate's spread while the encoder stands still: a load that changes at "
    "rest counts against every method alike, and an estimate that is steady but wrong looks perfect; "
    "a quiet estimate is a smoothed one, and on simulated logs its ranking does not follow the true "
    "error's (docs/metrics.md): read it as a noise figure, not as a ranking.",
    "`strain_delay_ms` is the estimate's lag behind the strain in the band where the two are "
    "coherent: the strain's own lag behind the torque is not in it, and a method that ignores "
    "the strain (current-based) may lead (negative).",
]


#: What a recorded log is ranked by, best first: the first of these that an ok row has
#: (``rms_error_rebuilt_nm`` only a log with a model reference has). Not ``rest_std_nm``:
#: its ranking does not follow the true one (docs/metrics.md).
RANKING_ORDER = ("rms_error_nm", "rms_error_rebuilt_nm", "rms_error_ref_nm", TRUTH_FREE_RANKING, "strain_delay_ms")


def ranking_column(frame) -> str:
    """The column the rows of a recorded log are ranked by: the first of :data:`RANKING_ORDER`
    that some ok row has a value in (:data:`TRUTH_FREE_RANKING` if none has)."""
    ok = measured_rows(frame)
    for column in RANKING_ORDER:
        if column in ok and np.isfinite(ok[column].astype(float)).any():
            return column
    return TRUTH_FREE_RANKING


def sort_key(values):
    """What a column is ranked by: ``strain_delay_ms`` by its absolute value (a lead is no
    better than a lag), the others as they are; lowest first."""
    values = values.astype(float)
    return values.abs() if values.name == "strain_delay_ms" else values


def shown_columns(frame) -> list[str]:
    """The columns of :data:`RECORDED_COLUMNS` that some ok row has a value in."""
    ok = measured_rows(frame)
    return [c for c in RECORDED_COLUMNS if c in ok and np.isfinite(ok[c].astype(float)).any()]


def log_table(rows, column: str):
    """One log's measured rows (:func:`~rippleb.report.stats.measured_rows`) sorted by ``column``
    (lowest first; methods without a value last),
    with a rank per shown column (``strain_delay_ms`` by its absolute value: a lead is no
    better than a lag)."""
    ok = measured_rows(rows).copy()
    for c in shown_columns(rows):
        ok[f"rank:{c}"] = sort_key(ok[c]).rank(method="min")
    ok["_key"] = sort_key(ok[column]) if column in ok else np.nan
    ok = ok.sort_values(["_key", "method"], na_position="last").drop(columns="_key")
    return ok.reset_index(drop=True)


def _cell(value, rank) -> str:
    if not np.isfinite(value):
        return "n/a"
    return f"{value:.3g}" + (f" ({int(rank)})" if np.isfinite(rank) else "")


def log_markdown(rows, name=markdown_text) -> str:
    """The table of one log: a line per method, best first by :func:`ranking_column`;
    ``name`` writes a method's name for the output (:func:`~rippleb.printable.escaped` for a
    terminal)."""
    column = ranking_column(rows)
    table = log_table(rows, column)
    columns = shown_columns(rows)
    cost = {r.method: r.p50 for r in timing_cells(rows, measured_rows(rows)).itertuples()}
    lines = []
    for i, r in enumerate(table.to_dict("records"), start=1):
        place = str(i) if np.isfinite(float(r.get(column, np.nan))) else "-"   # nothing to rank it by
        lines.append([place, name(r["method"])] + [_cell(float(r[c]), r[f"rank:{c}"]) for c in columns]
                     + [f"{cost[r['method']]:.3g}" if np.isfinite(cost.get(r["method"], np.nan)) else "n/a"])
    heads = ["rank", "method"] + list(columns) + ["p50 [us]"]
    return markdown(lines, heads) + f"\n\n{UNITS_NOTE}"


#: The title of the list of what each score cannot tell.
CAVEATS_TITLE = "What the scores cannot tell"
#: Under each table: the units, kept out of the headers so the run summary fits a terminal.
UNITS_NOTE = "Values in Nm (`strain_delay_ms` in ms), each with its rank in that column in brackets."


def basis_sentence(column: str, joint: dict | None = None) -> str:
    """Why the table is ranked by ``column``, and how far to trust it (the panel's agreement on
    the joint nearest to ``joint``, ``run.json``'s description of the log's joint)."""
    from rippleb.report.agreement import trust_sentence

    trust = trust_sentence(column, joint)
    return _basis(column, (joint or {}).get("reference_kind")) + (f" {trust}" if trust else "")


def _basis(column: str, kind: str | None) -> str:
    if column == "rms_error_nm":
        return "Ranked by `rms_error_nm`: the log has `torque_true`, so the error itself is known."
    if column == "rms_error_rebuilt_nm":
        return ("The log's `torque_ref` is a model torque, which lacks the gear's own torque: against it, a method "
                "that erases that real torque looks better. Ranked by `rms_error_rebuilt_nm`, the error against "
                "the torque rebuilt from the strain (the gauges' ripple taken out, the gear's torque kept); "
                "`rms_error_ref_nm` is shown beside it.")
    if column == "rms_error_ref_nm":
        if kind == "transducer":
            return ("Ranked by `rms_error_ref_nm`, the error against the log's `torque_ref`, a torque transducer "
                    "in series: the real torque, with the transducer's own noise and bandwidth in every row.")
        return ("Ranked by `rms_error_ref_nm`, the error against the log's `torque_ref`; if it is a model torque "
                "(the joint file says so in [joint.reference] kind), what the model leaves out counts as error and "
                "erasing the gear's own torque counts as accuracy: the log turns too little for the torque "
                "rebuilt from its strain.")
    head = "The log has neither `torque_true` nor `torque_ref`: no error can be computed."
    if column == TRUTH_FREE_RANKING:
        return (f"{head} Ranked by `{column}`, the truth-free score whose ranking agreed best with the "
                f"true one on simulated logs (docs/metrics.md).")
    return (f"{head} No run of motion in one direction spans two motor revolutions, so there is no "
            f"`{TRUTH_FREE_RANKING}`; ranked by the absolute `{column}`, whose ranking agreed only "
            f"weakly with the true one on simulated logs (docs/metrics.md).")


def leader_sentence(rows, column: str) -> str:
    """Who ranks first by ``column``, and what share of ``raw``'s ripple each method removed."""
    table = log_table(rows, column).dropna(subset=[column])
    if table.empty:
        return "No ok row has a value to rank by."
    first = table.iloc[0]
    text = f"{markdown_code(first['method'])} ranks first by `{column}` ({first[column]:.3g} {RECORDED_COLUMNS[column][1]})"
    raw = table[table["method"] == "raw"]
    if "ripple_wg_nm" in table and len(raw) and np.isfinite(raw["ripple_wg_nm"].iloc[0]) \
            and raw["ripple_wg_nm"].iloc[0] > 0:
        base = float(raw["ripple_wg_nm"].iloc[0])
        shares = [f"{markdown_code(r.method)} {1 - r.ripple_wg_nm / base:.0%}" for r in table.itertuples()
                  if r.method != "raw" and np.isfinite(r.ripple_wg_nm)]
        text += (f". Of the ripple at WG orders 2, 4, 8 that `raw` (the calibrated strain) holds, "
                 f"{base:.3g} Nm, each method removed: {', '.join(shares)}")
    return text + "."


def recorded_tables_markdown(frame, joint: dict | None = None) -> str:
    """The README's tables for a recorded log: per log, the ranking table and its basis, what
    the scores cannot tell, and the rows that did not finish ok. ``joint``: the log's joint as
    ``run.json`` records it (for how far to trust the ranking)."""
    parts = []
    for log in scenario_order(frame["scenario"].unique()):
        rows = frame[frame["scenario"] == log]
        column = ranking_column(rows)
        parts += [f"## {markdown_code(log)}: methods ranked by `{column}`", "", basis_sentence(column, joint), "",
                  log_markdown(rows) if len(measured_rows(rows)) else "(no rows to rank)", "",
                  f"- {leader_sentence(rows, column)}", ""]
    parts += [f"### {CAVEATS_TITLE}", ""] + [f"- {c}" for c in TRUTH_FREE_CAVEATS] + [""]
    parts += ["## Rows that did not finish ok", "", failed_markdown(frame)]
    return "\n".join(parts)


def recorded_summary_text(frame, joint: dict | None = None) -> str:
    """What ``rippleb run --log`` prints when it ends: per log, the ranking table and how far
    to trust it."""
    from rippleb.report.agreement import trust_sentence

    parts = []
    for log in scenario_order(frame["scenario"].unique()):
        rows = frame[frame["scenario"] == log]
        column = ranking_column(rows)
        n_ok = len(measured_rows(rows))
        parts += [f"{escaped(log)}: {plural(n_ok, 'ranked row')} of {len(rows)}, ranked by {column}", ""]
        parts += [log_markdown(rows, escaped) if n_ok else "(no rows to rank)", ""]
        trust = trust_sentence(column, joint) if n_ok else ""
        parts += [trust, ""] if trust else []
    failed = frame[~frame["status"].isin(MEASURED)]
    for r in failed.itertuples():
        parts.append(f"- {escaped(r.method)} / {escaped(r.scenario)}: {escaped(r.status)}: "
                     f"{one_line(first_line(r.message))}")
    return "\n".join(parts).rstrip()


def run_summary(frame, joint: dict | None = None) -> str:
    """The table ``rippleb run`` ends with: :func:`recorded_summary_text` for a recorded log
    (``joint`` as ``run.json`` records it), :func:`rippleb.report.tables.summary_text` for
    simulated devices."""
    if len(frame) and is_recorded(frame):
        return recorded_summary_text(frame, joint)
    return summary_text(frame)
