"""The report's Markdown as HTML: one source for the text of ``README.md`` and ``index.html``.

Every explanatory section of the report is written once, as Markdown (:mod:`rippleb.report.tables`,
:mod:`rippleb.report.recorded`, :mod:`rippleb.report.writer`); the HTML page shows the same
text through :func:`markdown_html`, which knows the little Markdown those sections use:
``##``-headings, paragraphs, ``- `` lists (a continuation line indented), GitHub tables,
`` `code` `` (any run of backticks as GitHub fences it), ``**bold**`` and backslash escapes.
Everything else is text, escaped for HTML: a method's or a file's name in a cell can hold no
markup of its own (:mod:`rippleb.printable` wrote it; tests/test_report_escaping.py renders both
pages' text with GitHub's cmark-gfm and compares).
"""

from __future__ import annotations

import html
import re

#: A backslash escape: a backslash and the ASCII punctuation mark it makes literal.
_ESCAPE = re.compile(r"\\([!-/:-@\[-`{-~])")
#: Stands for an unescaped ``**`` while a line is read; paired into <strong> at its end.
_BOLD = object()


def inline_html(text: str) -> str:
    """The Markdown of a sentence or a table cell as the report writes it, as HTML: its code
    spans (fenced by runs of backticks) as <code>, ``**bold**`` as <strong>, its backslash
    escapes resolved, and every character escaped for HTML (:func:`html.escape`). The same
    strings as the README, so both pages say the same; :func:`rippleb.printable.markdown_text`
    and ``markdown_code`` wrote whatever they hold that rippleb did not choose (an escaped
    ``\\*\\*`` is two stars, no bold)."""
    out, i, plain = [], 0, []

    def flush():
        out.append(html.escape("".join(plain)))
        plain.clear()

    while i < len(text):
        if text[i] == "\\" and i + 1 < len(text) and _ESCAPE.match(text, i):
            plain.append(text[i + 1])
            i += 2
            continue
        if text.startswith("**", i):
            flush()
            out.append(_BOLD)
            i += 2
            continue
        if text[i] == "`":
            run = len(text[i:]) - len(text[i:].lstrip("`"))
            fence = text[i:i + run]
            close = re.compile(f"(?<!`){fence}(?!`)").search(text, i + run)
            if close is not None:
                flush()
                body = text[i + run:close.start()]
                if len(body) > 1 and body[0] == body[-1] == " " and body.strip():
                    body = body[1:-1]
                out.append(f"<code>{html.escape(body)}</code>")
                i = close.end()
                continue
            plain.append(fence)
            i += run
            continue
        plain.append(text[i])
        i += 1
    flush()
    marks = [k for k, part in enumerate(out) if part is _BOLD]
    for n, k in enumerate(marks):   # in pairs; an odd last one is two stars
        out[k] = "**" if n == len(marks) - 1 and len(marks) % 2 else ("<strong>" if n % 2 == 0 else "</strong>")
    return "".join(out)


def cells(line: str) -> list[str]:
    """The cells of one table line ``| a | b |``, as GitHub reads them: split at the bars
    without a backslash before them (:func:`rippleb.report.markdown.markdown` writes a bar in
    a cell as ``\\|``), each ``\\|`` made a bar again before the cell is read as Markdown."""
    found, current, i = [], [], 1 if line.startswith("|") else 0
    end = len(line) - 1 if line.endswith("|") and not line.endswith("\\|") else len(line)
    while i < end:
        char = line[i]
        if char == "\\" and line[i + 1:i + 2] == "|":
            current.append("|")
            i += 2
            continue
        if char == "|":
            found.append("".join(current))
            current = []
        else:
            current.append(char)
        i += 1
    return found + ["".join(current)]


def _number(cell: str):
    try:
        return float(cell.split(" ")[0])
    except ValueError:
        return ""


def table_html(text: str, sort_column: int | None = None) -> str:
    """A GitHub Markdown table as a sortable HTML table; with ``sort_column``, its rows in
    ascending order of that column's number (rows without one last, as they were)."""
    lines = [[c.strip() for c in cells(line.strip())] for line in text.splitlines() if line.startswith("|")]
    if len(lines) < 2:
        return f"<p>{inline_html(text)}</p>"
    body = lines[2:]
    if sort_column is not None:
        body = sorted(body, key=lambda row: (_number(row[sort_column]) == "",
                                             _number(row[sort_column]) or 0.0) if sort_column < len(row)
                      else (True, 0.0))
    sorted_head = ' class="sorted-asc"'
    head = "".join(f'<th{sorted_head if i == sort_column else ""}>{inline_html(c)}</th>'
                   for i, c in enumerate(lines[0]))
    rows = []
    for row in body:
        tds = []
        for i, c in enumerate(row):
            v = _number(c)
            text_cell = i == 0 or v == ""  # names and words left-aligned, numbers right
            tds.append(f'<td class="{"text" if text_cell else ""}" data-v="{v}">{inline_html(c)}</td>')
        rows.append("<tr>" + "".join(tds) + "</tr>")
    return f'<table class="sortable"><thead><tr>{head}</tr></thead><tbody>{"".join(rows)}</tbody></table>'


def _first_numeric_column(text: str) -> int | None:
    """The first column of a Markdown table whose cells hold a number (after its name column)."""
    rows = [[c.strip() for c in cells(line.strip())] for line in text.splitlines() if line.startswith("|")][2:]
    for i in range(1, max((len(r) for r in rows), default=0)):
        if any(i < len(r) and _number(r[i]) != "" for r in rows):
            return i
    return None


def markdown_html(text: str, *, sort_tables: bool = False) -> str:
    """The Markdown of a report section as HTML (module docstring); with ``sort_tables``, each
    table in ascending order of its first numeric column, the score it ranks by."""
    out, lines, i = [], text.splitlines(), 0
    while i < len(lines):
        line = lines[i]
        if not line.strip():
            i += 1
        elif line.startswith("#"):
            level = min(len(line) - len(line.lstrip("#")), 6)
            out.append(f"<h{level}>{inline_html(line.lstrip('#').strip())}</h{level}>")
            i += 1
        elif line.startswith("|"):
            block = []
            while i < len(lines) and lines[i].startswith("|"):
                block.append(lines[i])
                i += 1
            table = "\n".join(block)
            out.append(table_html(table, _first_numeric_column(table) if sort_tables else None))
        elif line.startswith("- "):
            items = []
            while i < len(lines) and (lines[i].startswith("- ") or (items and lines[i].startswith("  "))):
                if lines[i].startswith("- "):
                    items.append(lines[i][2:].strip())
                else:
                    items[-1] += " " + lines[i].strip()
                i += 1
            out.append("<ul>" + "".join(f"<li>{inline_html(item)}</li>" for item in items) + "</ul>")
        else:
            block = []
            while i < len(lines) and lines[i].strip() and not lines[i].startswith(("#", "|", "- ")):
                block.append(lines[i].strip())
                i += 1
            out.append(f"<p>{inline_html(' '.join(block))}</p>")
    return "\n".join(out)
