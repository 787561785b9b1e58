"""Where each conclusion holds (rippleb/report/holds.py): the report's claims re-evaluated
at every value of a swept parameter, in the README and the HTML page alike."""

import numpy as np
import pandas as pd
import pytest

from rippleb.cli import main
from rippleb.errors import InputError
from rippleb.report import writer
from rippleb.report.holds import TITLE, blocks_markdown, holds_blocks
from rippleb.report.markdown_html import inline_html, markdown_html

PARAM = "gear.transmission_error"


def _rows(errors, seeds, **extra):
    """``{method: f(k)}`` on two scenarios, ``same-session``; ``k`` counts the devices from 0."""
    return [{"method": m, "scenario": s, "condition": "same-session", "seed": seed, "status": "ok",
             "rms_error_nm": f(k) + (0.1 if s == "reversal" else 0.0), **extra}
            for m, f in errors.items() for s in ("stop-restart", "reversal") for k, seed in enumerate(seeds)]


#: The report: ``a`` leads ``b`` on 16 devices; ``c`` trails.
REPORT = pd.DataFrame(_rows({"a": lambda k: 0.5 + 0.01 * k, "b": lambda k: 0.6 + 0.01 * k + 0.001 * k,
                             "c": lambda k: 1.0}, range(16)))


def _sweep(values=(0.0, 1e-4, 2e-4, 3e-4)):
    """At the first two values ``a`` leads ``b``, at the third neither does (the difference
    alternates in sign), at the last ``b`` leads; ``c`` is always last."""
    rows = []
    for v in values:
        gap = {0.0: 0.05, 1e-4: 0.04, 2e-4: None, 3e-4: -0.05}[v]
        b = ((lambda k: 0.5 + 0.01 * k + (-1) ** k * 0.002 * (k + 1)) if gap is None
             else (lambda k, g=gap: 0.5 + 0.01 * k + g + 0.001 * k))
        rows += _rows({"a": lambda k: 0.5 + 0.01 * k, "b": b, "c": lambda k: 1.5}, range(100, 110), **{PARAM: v})
    return pd.DataFrame(rows)


def test_each_claim_says_where_along_the_parameter_it_holds():
    blocks = holds_blocks(REPORT, [("runs/sw", _sweep())])
    assert blocks[0] == ("h2", TITLE)
    text = blocks_markdown(blocks)
    assert (f"`a` against `b` under `same-session`: `a` leads for `{PARAM}` <= 0.0001; not separated at "
            f"`{PARAM}` = 0.0002; `b` leads at `{PARAM}` = 0.0003.") in text
    assert (f"the lowest mean under `same-session`: `a` for `{PARAM}` <= 0.0001; `b` for `{PARAM}` >= 0.0002."
            in text)
    row = next(line for line in text.splitlines() if line.startswith("| `a` against `b` under `same-session` "))
    assert "(in this report: replicated)" in row
    assert [cell.strip() for cell in row.split("|")[2:-1]] == [
        "`a` leads (+0.0545 Nm, 10/10)", "`a` leads (+0.0445 Nm, 10/10)", "not separated (-0.001 Nm, 5/10)",
        "`b` leads (-0.0455 Nm, 0/10)"]
    assert f"`{PARAM}`: sweep `runs/sw`, 3 methods, 2 scenarios, 10 devices" in text
    rank = next(b for b in blocks if b[0] == "h4")
    assert rank[1].startswith("Each method's rank under `same-session` among the 3 swept methods")
    assert "| `c`      | 3   | 3        | 3        | 3        |" in text


def test_a_claim_whose_methods_the_sweep_did_not_run_is_left_out():
    sweep = _sweep()
    text = blocks_markdown(holds_blocks(REPORT, [("s", sweep[sweep["method"] != "b"])]))
    assert "the lowest mean under `same-session`: `a` at every value" in text
    assert "| `a` against `b`" not in text
    assert "No sweep ran the two methods and the condition of: `a` against `b` under `same-session`." in text


def test_a_grid_of_two_parameters_is_read_one_parameter_at_a_time():
    sweep = pd.concat([_sweep().assign(**{"ripple.drift": d}) for d in (0.0, 1.0)], ignore_index=True)
    heads = [b[1] for b in holds_blocks(REPORT, [("s", sweep)]) if b[0] == "h3"]
    assert f"`{PARAM}`, `ripple.drift` = 0: sweep `s`, 3 methods, 2 scenarios, 10 devices" in heads
    assert any(h.startswith(f"`ripple.drift`, `{PARAM}` = 0.0003: ") for h in heads)


def test_the_page_and_the_readme_say_the_same_things():
    """Both pages are written from the same blocks: every sentence and heading of the
    Markdown is in the HTML (back-ticks as <code>), every table as a table."""
    blocks = holds_blocks(REPORT, [("runs/sw", _sweep())])
    page = markdown_html(blocks_markdown(blocks))   # what html_report writes for the section
    tables = [content for kind, content in blocks if kind == "table"]
    assert page.count("<table") == len(tables)
    assert page.count("<tr>") == sum(content.count("\n") for content in tables)
    for kind, content in blocks:
        if kind != "table":
            for text in (content if kind == "ul" else [content]):
                assert inline_html(text) in page


def test_hostile_names_render_as_themselves():
    """Method labels, the condition and the sweep's path are anyone's text (a plugin's name,
    a results file, a directory; a swept column is one of rippleb's parameters): the section
    renders none of it as markup, on GitHub (cmark-gfm, raw HTML let through) and on the
    HTML page."""
    from support import HOSTILE, Page, render

    names = {"a": HOSTILE[0], "b": HOSTILE[4], "c": HOSTILE[2]}
    report, sweep = REPORT.replace({"method": names}), _sweep().replace({"method": names})
    report, sweep = (f.assign(condition=HOSTILE[7]) for f in (report, sweep))
    blocks = holds_blocks(report, [(HOSTILE[3], sweep)])
    page = Page(render(blocks_markdown(blocks)))
    assert set(page.tags()) <= {"h2", "h3", "h4", "p", "ul", "li", "table", "thead", "tbody", "tr", "th", "td",
                                "code"}, page.elements
    for text in (HOSTILE[0], HOSTILE[2], HOSTILE[3], HOSTILE[4], HOSTILE[7]):
        assert text in page.text, text
    html = Page(markdown_html(blocks_markdown(blocks)))
    assert set(html.tags()) <= {"h2", "h3", "h4", "p", "ul", "li", "table", "thead", "tbody", "tr", "th", "td",
                                "code"}, html.elements
    assert HOSTILE[0] in html.text


def test_a_directory_without_swept_values_is_one_line(tmp_path):
    from rippleb.engine.results import COLUMNS

    REPORT.reindex(columns=list(COLUMNS)).to_csv(tmp_path / "results.csv", index=False)
    with pytest.raises(InputError, match=r"--sweep .*: no swept parameter in its rows"):
        writer.load_sweep(tmp_path)


@pytest.mark.slow
def test_rippleb_report_reads_sweeps_through_the_cli(tmp_path):
    run = ["--methods", "raw,lowpass", "--scenarios", "static-contact", "--seeds", "2", "--jobs", "1", "--no-progress"]
    assert main(["run", *run, "--out", str(tmp_path / "run")]) == 0
    assert main(["sweep", "--param", f"{PARAM}=0,2.9e-4", *run, "--out", str(tmp_path / "sweep")]) == 0
    assert main(["report", str(tmp_path / "run"), "--no-figures", "--html", "--sweep", str(tmp_path / "sweep")]) == 0
    readme = (tmp_path / "run" / "report" / "README.md").read_text()
    page = (tmp_path / "run" / "report" / "index.html").read_text()
    assert f"## {TITLE}" in readme and f"<h2>{TITLE}</h2>" in page
    assert f"sweep `{tmp_path / 'sweep'}`, 2 methods, 1 scenario, 2 devices" in readme
    frame = writer.load_rows(tmp_path / "run")
    assert writer.holds_markdown(frame, [(str(tmp_path / "sweep"), writer.load_sweep(tmp_path / "sweep"))]) in readme
    assert np.all([line in page for line in ("lowest mean under", "swept methods")])
