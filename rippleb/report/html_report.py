"""``rippleb report DIR --html``: one self-contained, interactive ``index.html``.

The page holds what the README explains, in the README's own words (:mod:`rippleb.report.sections`
through :mod:`rippleb.report.markdown_html`: how to read the tables, the method x condition
summary and headline, what each method did with the gear's real torque, each method in
plain words, how timing was taken, how each method was tuned; for a recorded log its
ranking and how far to trust it), every table best first by the score it ranks by, a note
when only one condition ran; per condition a sortable table of every metric (mean ± 95 %
t-interval over seeds); interactive figures drawn with plotly (every row as a point whose
hover names its method, scenario, condition and seed; accuracy against cost; the signals
of one device, zoomable onto a restart), each method in its colour, marker and dash
(:mod:`rippleb.report.palette`); and the provenance. plotly.js is embedded once, in the
first figure, so the page opens without network. A small script at the top of the page lists any JavaScript error in the page
itself (``#page-errors``), so a reader, and the browser test, see a broken figure.
"""

from __future__ import annotations

import html
from pathlib import Path

import numpy as np

from rippleb.files import atomic_path
from rippleb.report.markdown_html import inline_html, markdown_html, table_html
from rippleb.report.palette import look
from rippleb.report.stats import (condition_order, fmt_interval, interval_frame, method_order, scenario_order,
                                  with_condition)

STYLE = """body{font-family:system-ui,sans-serif;margin:1.5em auto;max-width:1200px;color:#222}
table{border-collapse:collapse;margin:.5em 0 1.5em;font-size:13px}
th,td{border:1px solid #ccc;padding:3px 7px;text-align:right}
th{background:#f2f2f2;cursor:pointer;user-select:none}th:first-child,td:first-child,
td.text{text-align:left}th.sorted-asc::after{content:" \\25B2"}th.sorted-desc::after{content:" \\25BC"}
#page-errors{color:#b00}.wide{overflow-x:auto}.note{color:#555;font-size:13px}"""

#: Collects every uncaught error and rejected promise of the page into ``#page-errors``.
ERROR_HOOK = """window.pageErrors=[];function _pe(m){window.pageErrors.push(String(m));
var l=document.getElementById('page-errors');if(l){var i=document.createElement('li');
i.textContent=String(m);l.appendChild(i);}}
window.addEventListener('error',function(e){_pe(e.message||e);});
window.addEventListener('unhandledrejection',function(e){_pe(e.reason);});"""

#: Click a header to sort its table by that column (numbers by their mean, in data-v).
SORT_SCRIPT = """document.querySelectorAll('table.sortable th').forEach(function(th,col){
th.addEventListener('click',function(){var tb=th.closest('table').tBodies[0];
var asc=!th.classList.contains('sorted-asc');th.parentNode.querySelectorAll('th').forEach(
function(h){h.classList.remove('sorted-asc','sorted-desc');});th.classList.add(asc?'sorted-asc':'sorted-desc');
var rows=Array.from(tb.rows);rows.sort(function(a,b){var x=a.cells[col],y=b.cells[col];
var u=parseFloat(x.dataset.v),v=parseFloat(y.dataset.v);var r=(isNaN(u)||isNaN(v))?
x.textContent.localeCompare(y.textContent):(u-v);return asc?r:-r;});
rows.forEach(function(r){tb.appendChild(r);});});});"""


def write_html(frame, prov: dict, path, figure_seed: int | None = None, signals: dict | None = None,
               sweeps=()) -> Path:
    """Write the interactive report of ``frame`` to ``path`` and return it.

    Its explanatory sections are the README's own (:mod:`rippleb.report.sections`,
    :mod:`rippleb.report.recorded`), shown through :func:`~rippleb.report.markdown_html.markdown_html`;
    every table starts in order of the score it ranks by.

    Parameters
    ----------
    frame
        The result rows.
    prov
        The report's provenance (as :func:`rippleb.report.writer.report` builds it).
    figure_seed
        Device of the signal figure (stop-restart re-simulated and streamed), or None for
        figures from the rows only.
    signals
        ``{scenario: ScenarioSignals}`` already streamed for ``figure_seed`` (saves
        re-simulating them).
    sweeps
        ``[(name, rows)]`` of the sweeps the conclusions are re-evaluated on
        (:mod:`rippleb.report.holds`).
    """
    from rippleb.report.recorded import ranking_column
    from rippleb.report.sections import READING_RECORDED, READING_SIMULATED, conditions_note
    from rippleb.report.tables import counts_sentence, is_recorded, timing_note, title_lines

    frame = with_condition(frame)
    recorded = is_recorded(frame)
    column = ranking_column(frame) if recorded else "rms_error_nm"
    figures = [_rows_figure(frame, column), _cost_figure(frame, column)]
    restart = _restart_figure(frame, figure_seed, signals)
    if restart is not None:
        figures.append(restart)
    divs = [fig.to_html(full_html=False, include_plotlyjs=(i == 0), div_id=f"figure-{i}",
                        config={"responsive": True, "displaylogo": False})
            for i, fig in enumerate(figures)]
    title = title_lines(prov.get("published", False), recorded, str(prov.get("run_dir", "DIR")))
    note = conditions_note(frame)
    body = [f"<h1>{inline_html(title[0].lstrip('# '))}</h1>", f"<p>{inline_html(title[2])}</p>",
            f"<p>{inline_html(counts_sentence(frame, recorded))}</p>"]
    body += [f'<p class="note" id="conditions-note">{inline_html(note)}</p>'] if note else []
    body += ['<ul id="page-errors"></ul>', markdown_html(READING_RECORDED if recorded else READING_SIMULATED)]
    body += _recorded_body(frame, prov) if recorded else _simulated_body(frame)
    body += ["<h2>Every row</h2>", '<p class="note">One point per row (device); hover for method, '
             "scenario, condition and seed; drag to zoom, double-click to reset.</p>", divs[0],
             "<h2>Accuracy against per-tick cost</h2>", divs[1]]
    if restart is not None:
        body += [f"<h2>Signals of device seed {figure_seed} on stop-restart</h2>",
                 '<p class="note">Drag over a restart to zoom in; the legend toggles methods.</p>', divs[2]]
    for condition in condition_order(frame["condition"].unique()):
        body += [f"<h2>All metrics under <code>{html.escape(condition)}</code></h2>",
                 '<p class="note">Mean ± 95 % t-interval over seeds, each scenario best first by '
                 f'<code>{html.escape(column)}</code>; click a header to sort.</p>',
                 _metrics_table(frame[frame["condition"] == condition], column)]
    if sweeps and not recorded:
        from rippleb.report.holds import blocks_markdown, holds_blocks

        body.append(markdown_html(blocks_markdown(holds_blocks(frame, sweeps))))
    if not recorded:
        from rippleb.report.tuning_table import tuning_parts

        intro, table = tuning_parts(prov.get("run", {}).get("tuning"), method_order(frame["method"]))
        body += ["<h2>How each method was tuned</h2>", f"<p>{inline_html(intro)}</p>"]
        body += [table_html(table)] if table else []
    if "us_per_tick_p99" in frame:
        body += ["<h2>How timing was taken</h2>", f"<p>{inline_html(timing_note(prov, frame))}</p>"]
    body += ["<h2>Provenance</h2>", _provenance_table(prov)]
    page = ("<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>"
            f"<title>{html.escape(title[0].lstrip('# ').replace('`', ''))}</title><script>{ERROR_HOOK}</script>"
            f"<style>{STYLE}</style></head><body>" + "\n".join(body) +
            f"<script>{SORT_SCRIPT}</script></body></html>\n")
    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_text(page, encoding="utf-8")
    return path


# --------------------------------------------------------------------------- tables

def _simulated_body(frame) -> list[str]:
    """The README's summary (:func:`rippleb.report.sections.summary_sections`), each table best first."""
    from rippleb.report.sections import summary_sections

    return [markdown_html("\n".join(summary_sections(frame)), sort_tables=True)]


def _recorded_body(frame, prov: dict) -> list[str]:
    """A recorded log's ranking (:mod:`rippleb.report.recorded`), as the README has it."""
    from rippleb.report.recorded import recorded_tables_markdown

    return [markdown_html(recorded_tables_markdown(frame, prov.get("run", {}).get("joint")))]


def metric_columns(frame) -> list[str]:
    """Every numeric metric column of the rows that has a value, the truth-free ones and the
    error against the rebuilt torque included."""
    from rippleb.scoring.metrics import METRIC_COLUMNS
    from rippleb.scoring.rebuilt import REFERENCE_COLUMNS
    from rippleb.scoring.truthfree import TRUTH_FREE_COLUMNS

    return [c for c in METRIC_COLUMNS + TRUTH_FREE_COLUMNS + REFERENCE_COLUMNS if c in frame and frame[c].notna().any()]


def _metrics_table(rows, column: str = "rms_error_nm") -> str:
    """Every metric per method and scenario: the scenarios in their order, in each the methods
    best first by the mean of ``column`` (those without one last)."""
    columns = metric_columns(rows)
    stats = {c: {(r.method, r.scenario): r for r in interval_frame(rows, c).itertuples()}
             for c in dict.fromkeys(columns + [column])}
    head = "".join(f"<th>{html.escape(c)}</th>" for c in ["method", "scenario", "ok"] + columns)
    body = []
    for s in scenario_order(rows["scenario"].unique()):
        mine_s = rows[rows["scenario"] == s]
        means = {m: getattr(stats[column].get((m, s)), "mean", np.nan) for m in mine_s["method"].unique()}
        for m in sorted(method_order(list(means)), key=lambda m: (not np.isfinite(means[m]),
                                                                   means[m] if np.isfinite(means[m]) else 0.0)):
            mine = mine_s[mine_s["method"] == m]
            cells = [f'<td class="text">{html.escape(m)}</td>', f'<td class="text">{html.escape(s)}</td>',
                     f'<td data-v="{(mine["status"] == "ok").mean():.6g}">'
                     f'{(mine["status"] == "ok").sum()}/{len(mine)}</td>']
            for c in columns:
                r = stats[c].get((m, s))
                value = "" if r is None or not np.isfinite(r.mean) else f"{r.mean:.9g}"
                cells.append(f'<td data-v="{value}">{"n/a" if r is None else fmt_interval(r.mean, r.half)}</td>')
            body.append("<tr>" + "".join(cells) + "</tr>")
    return (f'<div class="wide"><table class="sortable"><thead><tr>{head}</tr></thead>'
            f'<tbody>{"".join(body)}</tbody></table></div>')


def _provenance_table(prov: dict) -> str:
    from rippleb.report.provenance import provenance_markdown

    return table_html(provenance_markdown(prov))


# --------------------------------------------------------------------------- figures

def _text(value) -> str:
    """A name as plotly's text: plotly reads tags and entities in legends, titles and hover
    labels (its own subset of HTML, links included), so a name is escaped for HTML."""
    return html.escape(str(value))


def _hover(rows):
    """The hover fields of each row: method, scenario, condition (escaped) and seed."""
    return np.column_stack([[_text(v) for v in rows[c]] for c in ("method", "scenario", "condition")]
                           + [rows["seed"]])


def _marker(method: str, index: int) -> dict:
    """``method``'s marker in a scatter (:mod:`rippleb.report.palette`): colour and symbol."""
    colour, symbol, _dash = look(method, index)
    return {"color": colour, "symbol": symbol}


def _line(method: str, index: int) -> dict:
    """``method``'s line in a signal figure: colour and dash."""
    colour, _symbol, dash = look(method, index)
    return {"color": colour, "dash": dash}


#: Axis titles of the figures per column they may plot (``rms_error_nm``, or what a recorded
#: log is ranked by).
AXIS_TITLES = {"rms_error_nm": "RMS error [Nm]", "rms_error_ref_nm": "RMS error against torque_ref [Nm]",
               "ripple_wg_nm": "ripple left at WG orders 2, 4, 8 [Nm]"}


def _rows_figure(frame, column: str = "rms_error_nm"):
    """``column`` of every ok row by scenario, one trace per method, one panel row per
    condition; hover shows method, scenario, condition, seed."""
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots

    ok = frame[frame["status"] == "ok"]
    conditions = condition_order(ok["condition"].unique()) or ["same-session"]
    fig = make_subplots(rows=len(conditions), cols=1, shared_xaxes=True,
                        subplot_titles=[f"condition {_text(c)}" for c in conditions], vertical_spacing=0.08)
    methods = method_order(ok["method"].unique())
    scenarios = scenario_order(ok["scenario"].unique())
    for k, condition in enumerate(conditions, start=1):
        rows = ok[ok["condition"] == condition]
        for i, m in enumerate(methods):
            mine = rows[rows["method"] == m]
            fig.add_trace(go.Scatter(
                x=[scenarios.index(s) + (i - len(methods) / 2) * 0.08 for s in mine["scenario"]],
                y=mine[column], mode="markers", name=_text(m), legendgroup=m, showlegend=(k == 1),
                marker={**_marker(m, i), "size": 7, "opacity": 0.8},
                customdata=_hover(mine),
                hovertemplate="method %{customdata[0]}<br>scenario %{customdata[1]}<br>condition "
                              "%{customdata[2]}<br>seed %{customdata[3]}<br>" + column + " %{y:.4g}<extra></extra>"),
                row=k, col=1)
        fig.update_yaxes(type="log", title_text=AXIS_TITLES.get(column, column), row=k, col=1)
    fig.update_xaxes(tickvals=list(range(len(scenarios))), ticktext=[_text(s) for s in scenarios])
    fig.update_layout(height=320 * len(conditions) + 80, margin={"t": 40, "b": 40}, legend={"orientation": "h"})
    return fig


def _cost_figure(frame, column: str = "rms_error_nm"):
    """Every ok row: ``us_per_tick_p50`` against ``column``, hover names the row."""
    import plotly.graph_objects as go

    ok = frame[frame["status"] == "ok"]
    cost = "us_per_tick_p50" if "us_per_tick_p50" in ok else "us_per_tick_p99"
    fig = go.Figure()
    for i, m in enumerate(method_order(ok["method"].unique())):
        mine = ok[ok["method"] == m]
        fig.add_trace(go.Scatter(
            x=mine[cost], y=mine[column], mode="markers", name=_text(m), marker={**_marker(m, i), "size": 7},
            customdata=_hover(mine),
            hovertemplate="method %{customdata[0]}<br>scenario %{customdata[1]}<br>condition %{customdata[2]}"
                          "<br>seed %{customdata[3]}<br>" + cost + " %{x:.3g} us<br>" + column
                          + " %{y:.4g}<extra></extra>"))
    title = "RMS error against torque_true [Nm]" if column == "rms_error_nm" else AXIS_TITLES.get(column, column)
    fig.update_layout(xaxis={"type": "log", "title": f"{cost} [us]"},
                      yaxis={"type": "log", "title": title},
                      height=480, margin={"t": 30})
    return fig


def _restart_figure(frame, seed, signals):
    """Each method's estimate and torque_true on stop-restart for ``seed``, at the control
    rate (the last sample of each tick: what a controller reads), zoomable."""
    import plotly.graph_objects as go

    from rippleb.simulator.conditions import DEFAULT_CONDITION

    ok = frame[(frame["status"] == "ok") & (frame["condition"] == DEFAULT_CONDITION)]
    if seed is None or "stop-restart" not in set(ok["scenario"]):
        return None
    sig = (signals or {}).get("stop-restart")
    if sig is None:   # re-streamed in the methods' sandboxed workers, as the figures are
        from rippleb.report.plotting import restream

        sig = restream(method_order(ok["method"].unique()), ["stop-restart"], seed)[0]["stop-restart"]
    log = sig.sim.log
    every = max(1, int(round(log.spec.fs / log.spec.control_rate)))
    pick = slice(every - 1, None, every)
    fig = go.Figure()
    fig.add_trace(go.Scatter(x=log.t[pick], y=log.torque_true[pick], name="torque_true",
                             line={"color": "black", "width": 2}))
    for i, m in enumerate(method_order(sig.estimates)):
        fig.add_trace(go.Scatter(x=log.t[pick], y=sig.estimates[m][pick], name=_text(m),
                                 line={**_line(m, i), "width": 1}))
    fig.update_layout(xaxis={"title": "time [s]", "rangeslider": {"visible": True}},
                      yaxis={"title": "torque [Nm]"}, height=520, margin={"t": 30})
    return fig
