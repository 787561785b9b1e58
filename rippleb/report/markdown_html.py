"""The report's Markdown as HTML: one source for the text of ``README.md`` and ``index.html``.

Every explanatory section of the report is written once, as Markdown (:mod:`rippleb.report.tables`,
:mod:`rippleb.report.recorded`, :mod:`rippleb.report.writer`); the HTML page shows the same
text through :func:`markdown_html`, which knows the little Markdown those sections use:
``##``-headings, paragraphs, ``- `` lists (a continuation line indented), GitHub tables,
`` `code` `` and ``**bold**``. Everything else is text, escaped: a method's or a file's name
in a cell can hold no markup of its own.
"""

from __future__ import annotations

import html
import re

#: A bar that ends a cell: not escaped (``rippleb.report.markdown.markdown`` writes a bar in a cell as ``\|``).
_CELL_BAR = re.compile(r"(?<!\\)\|")


def inline_html(text: str) -> str:
    """``text`` escaped, with `` `code` `` and ``**bold**`` as HTML."""
    parts = html.escape(text).split("`")
    out = []
    for i, part in enumerate(parts):
        if i % 2:
            out.append(f"<code>{part}</code>")
        else:
            out.append(re.sub(r"\*\*(.+?)\*\*", r"<strong>\1</strong>", part))
    return "".join(out)


def _number(cell: str):
    try:
        return float(cell.split(" ")[0])
    except ValueError:
        return ""


def table_html(text: str, sort_column: int | None = None) -> str:
    """A GitHub Markdown table as a sortable HTML table; with ``sort_column``, its rows in
    ascending order of that column's number (rows without one last, as they were)."""
    lines = [[c.replace("\\|", "|").strip() for c in _CELL_BAR.split(line.strip()[1:-1])]
             for line in text.splitlines() if line.startswith("|")]
    if len(lines) < 2:
        return f"<p>{html.escape(text)}</p>"
    body = lines[2:]
    if sort_column is not None:
        body = sorted(body, key=lambda cells: (_number(cells[sort_column]) == "",
                                               _number(cells[sort_column]) or 0.0) if sort_column < len(cells)
                      else (True, 0.0))
    sorted_head = ' class="sorted-asc"'
    head = "".join(f'<th{sorted_head if i == sort_column else ""}>{html.escape(c)}</th>'
                   for i, c in enumerate(lines[0]))
    rows = []
    for cells in body:
        tds = []
        for i, c in enumerate(cells):
            v = _number(c)
            text_cell = i == 0 or v == ""  # names and words left-aligned, numbers right
            tds.append(f'<td class="{"text" if text_cell else ""}" data-v="{v}">{html.escape(c)}</td>')
        rows.append("<tr>" + "".join(tds) + "</tr>")
    return f'<table class="sortable"><thead><tr>{head}</tr></thead><tbody>{"".join(rows)}</tbody></table>'


def _first_numeric_column(text: str) -> int | None:
    """The first column of a Markdown table whose cells hold a number (after its name column)."""
    rows = [[c.strip() for c in _CELL_BAR.split(line.strip()[1:-1])] for line in text.splitlines()
            if line.startswith("|")][2:]
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
