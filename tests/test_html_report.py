"""rippleb report --html: the self-contained interactive page, unit-tested on synthetic rows
and opened end to end in headless Chromium."""

import os
import re
import shutil
import subprocess

import numpy as np
import pandas as pd
import pytest

from rippleb.report import html_report
from rippleb.scoring.metrics import METRIC_COLUMNS

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync"]


def conditions_frame(seeds=4):
    """Rows of three methods on two scenarios under two conditions; kalman-ripple leads
    under same-session and falls behind order-tracking under re-assembled."""
    rng = np.random.default_rng(3)
    base = {("same-session", "kalman-ripple"): 0.2, ("re-assembled", "kalman-ripple"): 1.0}
    rows = []
    for condition in ("same-session", "re-assembled"):
        for method in ("raw", "order-tracking", "kalman-ripple"):
            for scenario in ("paper-quintic", "creep"):
                for seed in range(seeds):
                    level = base.get((condition, method), {"raw": 2.0, "order-tracking": 0.5}.get(method))
                    rows.append({"method": method, "scenario": scenario, "condition": condition, "seed": seed,
                                 "status": "ok", "message": "",
                                 "rms_error_nm": level * (1 + 0.05 * rng.standard_normal()),
                                 "max_error_nm": 3 * level, "rms_error_ref_nm": level, "max_error_ref_nm": 3 * level,
                                 "delay_ms": 1.0, "us_per_tick_p50": 5.0, "us_per_tick_p99": 12.0})
    # every metric column a results file has (the reader refuses a file without one)
    return pd.DataFrame(rows).reindex(columns=list(dict.fromkeys([*rows[0], *METRIC_COLUMNS])))


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
    assert "The lowest mean depends on the condition" in page
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


@pytest.mark.slow
def test_page_renders_in_headless_chromium_without_javascript_errors(tmp_path):
    if CHROMIUM is None:
        if os.environ.get("CI") == "true":
            pytest.fail("chromium is not installed; .ci/run installs Debian's chromium package")
        pytest.skip("chromium is not installed (apt-get install chromium); CI runs this test")
    from rippleb.report.writer import report

    run = tmp_path / "run"
    run.mkdir()
    conditions_frame().to_csv(run / "results.csv", index=False)
    out = tmp_path / "report"
    page = report(run, out, figures=False, html=True, argv=["report", str(run), "--html"])["html"]
    url = page.resolve().as_uri()
    dom = _chromium(["--dump-dom", url], tmp_path, "dom")
    assert dom.returncode == 0, dom.stderr[-2000:]
    html = dom.stdout
    # plotly drew each figure: its SVG layers are in the DOM
    assert html.count('class="main-svg"') >= 2 * 2, "plots did not render"
    assert re.search(r'<ul id="page-errors">\s*</ul>', html), "the page logged a JavaScript error: " + \
        re.search(r'<ul id="page-errors">(.*?)</ul>', html, re.S).group(1)[:500]
    assert "Uncaught" not in dom.stderr
    assert html.count("<table") >= 4 and "kalman-ripple" in html
    shot = out / "screenshot.png"
    snap = _chromium([f"--screenshot={shot}", "--window-size=1300,2400", url], tmp_path, "shot")
    assert snap.returncode == 0, snap.stderr[-2000:]
    assert shot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and shot.stat().st_size > 50_000
    keep = os.environ.get("RIPPLEB_SCREENSHOT")
    if keep:  # for a person to look at
        shutil.copyfile(shot, keep)
