"""Issue 41, item 4: a report cannot be turned against its reader.

Every string a method or a file name contributes (a method's label and message, a scenario
or log file's name, a condition read from a results file, the recorded command line) is
written so that it renders as itself: in ``README.md`` (checked by rendering it with
GitHub's own renderer, cmark-gfm, with raw HTML let through and no tag filter: the
strictest reading), in ``index.html`` (parsed), and in the figures (matplotlib's mathtext).
"""

from __future__ import annotations

import re

import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from rippleb.printable import escaped, markdown_code, markdown_text
from rippleb.report import html_report
from rippleb.report.markdown import markdown, one_line
from rippleb.report.markdown_html import inline_html, table_html
from support import HOSTILE, Page, render

cmark = pytest.importorskip("cmarkgfm.cmark")

#: Elements a report's README renders to (its own words set one in bold); no text of a row makes another.
README_ELEMENTS = {"h1", "h2", "h3", "h4", "p", "ul", "li", "table", "thead", "tbody", "tr", "th", "td",
                   "code", "img", "a", "strong"}



# Any text, with the characters and sequences Markdown and HTML act on made frequent.
_TRICKY = st.sampled_from(list("\\`*_[]<>&~$!#+-=|():/\"' \t\n") +
                          ["javascript:", "<img src=x onerror=alert(1)>", "``", "](", "&lt;", "www.x.org",
                           "http://x.org", "\u2028", "\x1b[2J"])
TEXTS = st.lists(st.one_of(st.characters(codec="utf-8"), _TRICKY), max_size=30).map("".join)


@settings(max_examples=400, suppress_health_check=list(HealthCheck))
@given(TEXTS)
def test_markdown_text_renders_as_itself_in_a_sentence_a_list_item_and_a_cell(value):
    shown = escaped(value)
    page = Page(render(f"w {markdown_text(value)} z"))
    # an e-mail address in the text is linked by GitHub's autolink extension (mailto:, harmless)
    assert set(page.tags()) <= {"p", "a"}, page.elements
    assert all(attrs.get("href", "").startswith("mailto:") for tag, attrs in page.elements if tag == "a")
    assert page.text.strip("\n") == f"w {shown} z"
    page = Page(render(f"- w {markdown_text(value)} z"))
    assert set(page.tags()) <= {"ul", "li", "a"} and page.text.strip() == f"w {shown} z"
    page = Page(render(markdown([["w" + markdown_text(value)]], ["head"])))
    assert set(page.tags()) <= {"table", "thead", "tbody", "tr", "th", "td", "a"}
    assert page.text.split("head", 1)[1].strip() == ("w" + shown).strip()


@settings(max_examples=400, suppress_health_check=list(HealthCheck))
@given(TEXTS)
def test_markdown_code_renders_as_itself_in_a_sentence_and_a_cell(value):
    shown = escaped(value)
    if not shown.strip():
        assert markdown_code(value) in ("", f"`{shown}`")
        return
    page = Page(render(f"w {markdown_code(value)} z"))
    assert page.tags() == ["p", "code"] and page.text.strip("\n") == f"w {shown} z"
    page = Page(render(markdown([[markdown_code(value)]], ["head"])))
    assert page.tags() == ["table", "thead", "tr", "th", "tbody", "tr", "td", "code"]
    assert page.text.split("head", 1)[1].strip("\n") == shown


@settings(max_examples=300, suppress_health_check=list(HealthCheck))
@given(TEXTS)
def test_the_html_page_renders_the_report_s_markdown_as_github_does(value):
    """index.html renders the README's sentences and cells itself: the same text as cmark-gfm."""
    for written in (markdown_text(value), markdown_code(value)):
        sentence = f"w {written} z"
        assert Page(inline_html(sentence)).text == Page(render(sentence)).text.strip("\n")
        ours = Page(table_html(markdown([[written]], ["head"])))
        assert set(ours.tags()) <= {"table", "thead", "tbody", "tr", "th", "td", "code"}
        github = Page(render(markdown([[written]], ["head"])))
        assert ours.text.split("head", 1)[1].strip() == github.text.split("head", 1)[1].strip()


def hostile_frame():
    """Rows whose every text field carries markup: method labels, scenario and condition
    names, a status-error message (as a results file someone else wrote could hold)."""
    from support import conditions_frame

    frame = conditions_frame(seeds=3)
    names = {"raw": f'hostile[tag="{HOSTILE[0]}"]', "order-tracking": HOSTILE[4], "kalman-ripple": "kalman-ripple"}
    frame["method"] = frame["method"].map(names)
    frame["scenario"] = frame["scenario"].map({"paper-quintic": HOSTILE[1], "creep": HOSTILE[7]})
    frame["condition"] = frame["condition"].map({"same-session": "same-session", "re-assembled": HOSTILE[2]})
    failed = frame.index[:2]
    frame.loc[failed, "status"] = "error"
    frame.loc[failed, "message"] = "RuntimeError: " + " ".join(HOSTILE)
    frame.loc[failed, "rms_error_nm"] = float("nan")
    return frame


PROV = {"run": {"command": f"rippleb run --scenarios '{HOSTILE[1]}.toml' --out {HOSTILE[3]}", "jobs": HOSTILE[0],
                "resumes": [HOSTILE[4]], "cpu": HOSTILE[2], "versions": {"numpy": HOSTILE[1]},
                "machine": {"numerics": HOSTILE[0]},
                "tuning": {"protocol": {"budget": HOSTILE[1], "seeds": [HOSTILE[2]], "sampler": HOSTILE[3],
                                        "criterion": "c", "rule": "r"},
                           "methods": {"kalman-ripple": {"adopted": {HOSTILE[4]: HOSTILE[0]}, "evaluations": 2}}}},
        "report": {"command": "rippleb report"}, "seeds_text": "0-2 (3 seeds)", "published": False,
        "run_dir": HOSTILE[1]}


def _no_markup_from_the_rows(page: Page, allowed: set[str]) -> None:
    for tag, attrs in page.elements:
        assert tag in allowed, (tag, attrs)
        assert not any(name.startswith("on") for name in attrs), (tag, attrs)
        for name in ("href", "src"):
            assert not attrs.get(name, "figures/").lower().lstrip().startswith("javascript"), (tag, attrs)


def test_a_readme_of_hostile_names_messages_and_provenance_renders_none_of_it():
    from rippleb.report import writer

    readme = writer.readme_markdown(hostile_frame(), PROV, {}, run_dir=HOSTILE[1])
    page = Page(render(readme))
    _no_markup_from_the_rows(page, README_ELEMENTS - {"a", "img"})
    for text in HOSTILE[:5]:   # each shown as the text it is
        assert text in page.text, text
    assert one_line("RuntimeError: " + " ".join(HOSTILE)) in page.text   # the message cell, cut at 200


def test_the_html_page_of_the_same_rows_holds_none_of_it(tmp_path):
    prov = {**PROV, "run": {k: v for k, v in PROV["run"].items() if k != "tuning"}}
    text = html_report.write_html(hostile_frame(), prov, tmp_path / "index.html").read_text()
    page = Page(text)
    assert not [attrs for tag, attrs in page.elements if tag == "img" or any(a.startswith("on") for a in attrs)]
    # the page's own scripts only: the error hook, plotly's configuration and plotly.js (embedded
    # once), the two figures, the sorter
    assert page.tags().count("script") == len(re.findall(r"<script\b", text)) == 6
    for value in HOSTILE[:5]:
        assert value in page.text
    # the figures' names reach plotly escaped: plotly reads tags in legends and hover labels
    assert "&lt;img src=x onerror=alert(2)&gt;" in text.replace("\\u003c", "<").replace("\\u003e", ">")


def test_figures_draw_names_that_are_not_mathtext(tmp_path):
    """A name with ``$...$`` that is not valid mathtext stopped the whole report (a
    ParseFatalException while saving the cost figure)."""
    from rippleb.report.error_figures import plot_accuracy_vs_cost

    frame = hostile_frame()
    frame["method"] = frame["method"].replace({"kalman-ripple": "m[p=\"$\\x$\"]"})
    path = plot_accuracy_vs_cost(frame, tmp_path / "cost.png")
    assert path.read_bytes().startswith(b"\x89PNG")
