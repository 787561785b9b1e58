"""rippleb report --html: the self-contained interactive page, unit-tested on synthetic rows
and opened end to end in headless Chromium."""

import html
import os
import re
import shutil
import subprocess

import numpy as np
import pandas as pd
import pytest

from rippleb.report import html_report
from rippleb.report.stats import METHOD_ORDER
from rippleb.scoring.metrics import METRIC_COLUMNS
from support import conditions_frame

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync"]


PROV = {"run": {"command": "rippleb run", "jobs": 2, "cpu_count": 2}, "report": {"command": "rippleb report"},
        "seeds_text": "0-3 (4 seeds)", "published": False, "run_dir": "runs/x"}


def test_page_is_self_contained_with_tables_per_condition_and_headline(tmp_path):
    page = html_report.write_html(conditions_frame(), PROV, tmp_path / "index.html").read_text()
    assert page.count("<script") >= 3
    assert not re.search(r"<script[^>]+src=", page), "the page must not load scripts from elsewhere"
    # plotly.js embedded exactly once (its version banner), and every figure drawn with it
    assert len(re.findall(r"plotly\.js v\d", page)) == 1
    assert page.count("Plotly.newPlot") == 2  # rows and cost; no signals without a figure seed
    assert "All metrics under <code>same-session</code>" in page
    assert "All metrics under <code>re-assembled</code>" in page
    assert "Over every device, the lowest mean depends on the condition" in page
    assert "<h2>Headlines</h2>" in page and "No claim of who leads under a condition replicated" in page
    assert page.count('class="sortable"') == 4  # summary, two conditions, provenance
    assert "report of <code>runs/x</code>" in page
    assert "How each method was tuned" in page and "Not recorded" in page


def test_page_shows_the_tuning_the_run_recorded(tmp_path):
    from rippleb.tuning import read_record, summary

    prov = {**PROV, "run": {**PROV["run"], "tuning": summary()}}
    page = html_report.write_html(conditions_frame(), prov, tmp_path / "index.html").read_text()
    adopted = read_record()["methods"]["order-tracking"]["adopted"]
    assert page.count('class="sortable"') == 5  # and the tuning table
    # a table cell's Markdown is rendered as the README renders it: its code spans as <code>
    assert f"<code>q</code> = {adopted['q']:g}" in page


def test_hover_of_every_row_names_method_scenario_condition_and_seed(tmp_path):
    fig = html_report._rows_figure(html_report.with_condition(conditions_frame(seeds=2)))
    points = sum(len(trace.y) for trace in fig.data)
    assert points == 24
    trace = fig.data[0]
    assert "seed %{customdata[3]}" in trace.hovertemplate and "method %{customdata[0]}" in trace.hovertemplate
    assert list(trace.customdata[0][:2]) == ["raw", "paper-quintic"]


def _chromium(args, tmp_path, name):
    profile = tmp_path / f"profile-{name}"
    cmd = [CHROMIUM, *CHROMIUM_FLAGS, f"--user-data-dir={profile}", "--virtual-time-budget=15000", *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=180)


def _rendered(tmp_path, frame, name):
    """The DOM of ``frame``'s report page after Chromium ran its scripts, and the page's path."""
    from rippleb.report.writer import report

    run = tmp_path / f"run-{name}"
    run.mkdir()
    frame.to_csv(run / "results.csv", index=False)
    out = tmp_path / f"report-{name}"
    page = report(run, out, figures=False, html=True, argv=["report", str(run), "--html"])["html"]
    dom = _chromium(["--dump-dom", page.resolve().as_uri()], tmp_path, f"dom-{name}")
    assert dom.returncode == 0, dom.stderr[-2000:]
    text = dom.stdout
    assert re.search(r'<ul id="page-errors">\s*</ul>', text), "the page logged a JavaScript error: " + \
        re.search(r'<ul id="page-errors">(.*?)</ul>', text, re.S).group(1)[:500]
    assert "Uncaught" not in dom.stderr
    return text, page, out


@pytest.mark.slow
def test_page_renders_in_headless_chromium_without_javascript_errors(tmp_path):
    if CHROMIUM is None:
        if os.environ.get("CI") == "true":
            pytest.fail("chromium is not installed; .ci/run installs Debian's chromium package")
        pytest.skip("chromium is not installed (apt-get install chromium); CI runs this test")
    text, page, out = _rendered(tmp_path, conditions_frame(), "conditions")
    # plotly drew each figure: its SVG layers are in the DOM
    assert text.count('class="main-svg"') >= 2 * 2, "plots did not render"
    assert text.count("<table") >= 4 and "kalman-ripple" in text
    assert "Reading these tables</h2>" in text and 'id="conditions-note"' not in text
    shot = out / "screenshot.png"
    snap = _chromium([f"--screenshot={shot}", "--window-size=1300,2400", page.resolve().as_uri()], tmp_path, "shot")
    assert snap.returncode == 0, snap.stderr[-2000:]
    assert shot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and shot.stat().st_size > 50_000
    keep = os.environ.get("RIPPLEB_SCREENSHOT")
    if keep:  # for a person to look at
        shutil.copyfile(shot, keep)

    # issue 39: every built-in method, one condition: every section, the note, the tables best
    # first and a legend entry per method, as the browser shows them
    text, _page, _out = _rendered(tmp_path, builtins_frame(), "builtins")
    for title in ("Reading these tables", "What each method did with the gear's real torque",
                  "Each method in plain words", "How timing was taken"):
        assert re.search(rf">{re.escape(title)}</h[23]>", text), title
    assert re.search(r'id="conditions-note">Only the condition <code>same-session</code> ran', text)
    assert text.count('class="legendtoggle"') >= len(BUILTINS), "the legend lost a method"
    summary = text[text.index("Method x condition"):]
    assert re.findall(r'<tr><td class="text" data-v="">([a-z-]+)</td>', summary)[0] == BUILTINS[-1]


# ------------------------------------------------------------------ issue 39: the page says why
BUILTINS = list(METHOD_ORDER)


def builtins_frame(conditions=("same-session",), seeds=3):
    """Every built-in method on two scenarios, its error falling with its place in BUILTINS
    reversed (gear-aware best), with the gear's columns."""
    rng = np.random.default_rng(5)
    rows = []
    for condition in conditions:
        for i, method in enumerate(BUILTINS):
            for scenario in ("paper-quintic", "creep"):
                for seed in range(seeds):
                    level = 2.0 - 0.1 * i
                    rows.append({"method": method, "scenario": scenario, "condition": condition, "seed": seed,
                                 "status": "ok", "message": "",
                                 "rms_error_nm": level * (1 + 0.02 * rng.standard_normal()),
                                 "max_error_nm": 3 * level, "rms_error_ref_nm": level, "max_error_ref_nm": 3 * level,
                                 "delay_ms": 1.0, "gear_torque_rms_nm": 0.5, "gear_removed_fraction": 0.05 * i,
                                 "rms_error_without_gear_nm": level / 2, "us_per_tick_p50": 5.0,
                                 "us_per_tick_p99": 12.0})
    return pd.DataFrame(rows).reindex(columns=list(dict.fromkeys([*rows[0], *METRIC_COLUMNS])))


def test_the_page_says_what_the_readme_explains_from_the_same_text(tmp_path):
    """Issue 39: the page left out "Reading these tables", "What each method did with the gear's
    real torque" and "Each method in plain words"; each is now the README's own Markdown."""
    from rippleb.report.markdown_html import inline_html, markdown_html
    from rippleb.report.gear_section import gear_markdown
    from rippleb.report.sections import READING_SIMULATED, verdicts_section
    from rippleb.report.writer import readme_markdown

    frame = builtins_frame(("same-session", "re-assembled"))
    page = html_report.write_html(frame, PROV, tmp_path / "index.html").read_text()
    readme = readme_markdown(frame, {**PROV, "report": PROV["report"], "seeds_text": "0-2", "rows": len(frame),
                                     "statuses": {"ok": len(frame)}}, {})
    for title in ("Reading these tables", "What each method did with the gear's real torque",
                  "Each method in plain words", "How timing was taken"):
        assert f">{html.escape(title)}</h" in page and f"# {title}" in readme, title
    assert markdown_html(READING_SIMULATED) in page
    sections = html_report.with_condition(frame)
    for text in (gear_markdown(sections), verdicts_section(sections)):
        for line in [t for t in text if t.startswith("- ")]:   # each sentence, from the one source
            assert f"<li>{inline_html(line[2:])}</li>" in page, line


def test_every_table_starts_best_first(tmp_path):
    """Issue 39: the page's tables were in registry order."""
    page = html_report.write_html(builtins_frame(), PROV, tmp_path / "index.html").read_text()
    summary = page[page.index("Method x condition"):]
    first_rows = re.findall(r'<tr><td class="text" data-v="">([a-z-]+)</td>', summary)
    assert first_rows[:len(BUILTINS)] == BUILTINS[::-1], first_rows[:5]   # the last has the lowest mean
    metrics = page[page.index("All metrics under"):]
    assert re.findall(r'<tr><td class="text">([a-z-]+)</td>', metrics)[:3] == BUILTINS[::-1][:3]


def test_every_built_in_method_is_told_apart_by_colour_marker_and_dash(tmp_path):
    from rippleb.report.palette import look

    looks = [look(m, i) for i, m in enumerate(BUILTINS + ["plugin-a", "plugin-b", "plugin-c"])]
    assert len({(colour, marker) for colour, marker, _ in looks}) == len(looks)   # markers alone tell them apart
    assert len({colour for colour, _, _ in looks}) >= 7
    fig = html_report._rows_figure(html_report.with_condition(builtins_frame()))
    shown = {(t.marker.color, t.marker.symbol) for t in fig.data}
    assert len(shown) == len(BUILTINS) == len(fig.data)


def test_a_run_of_one_condition_says_how_to_run_the_others(tmp_path):
    one = html_report.write_html(builtins_frame(), PROV, tmp_path / "one.html").read_text()
    assert 'id="conditions-note"' in one and "<code>rippleb run --conditions all</code>" in one
    two = html_report.write_html(conditions_frame(), PROV, tmp_path / "two.html").read_text()
    assert 'id="conditions-note"' not in two
