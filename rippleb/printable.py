"""Text from code rippleb does not trust, made safe to print and to write: one escaping per output.

rippleb prints and writes strings it does not choose: a method's error message and its
label (``NAME[p="..."]``), a plugin's import error, a scenario or log file's name, a cell
of a results file or a field of a run directory someone else wrote, the recorded command
line. Each output format gets them through its own function, here (HTML through
:func:`html.escape`, the standard library's):

* a terminal, a log line, and every other output first: :func:`escaped`. An escape
  sequence that reaches a terminal can move its cursor, rewrite lines already printed,
  retitle the window or, on some terminals, answer back; in a README or a CSV a newline
  or carriage return forges a line. Every such character is spelled as a visible escape
  (``ESC`` becomes ``\\x1b``), so the text stays readable and cannot act. It is applied
  where such text enters a row (the runner's results) and again wherever rows or
  messages are printed or written, so a results file edited by hand is no way around it.
* Markdown (a report's ``README.md``): :func:`markdown_text` in running text and table
  cells, :func:`markdown_code` in a code span. Written as it is, ``<img src=x onerror=...>``
  is an HTML element and ``[x](javascript:...)`` a link wherever the README is rendered
  (GitHub's own renderer passes ``<img onerror>`` to its sanitizer; others pass it to the
  browser). CommonMark 0.31 ("Backslash escapes", "Code spans") and GitHub's extensions
  (tables, autolinks, strike-through, math) say what acts.
* CSV (``results.csv`` and every CSV a report writes): :func:`csv_text`, read back by
  :func:`csv_read`. A spreadsheet runs a cell that starts with ``=``, ``+``, ``-`` or
  ``@`` as a formula (``=HYPERLINK(...)``, ``=cmd|...``, OWASP "CSV Injection").
"""

from __future__ import annotations

import re

#: C0 controls, DEL and C1 controls (ECMA-48: the bytes a terminal acts on), and the
#: Unicode line and paragraph separators, which some readers break lines at.
_CONTROL = re.compile("[\x00-\x1f\x7f-\x9f\u2028\u2029]")


def _visible(match: re.Match) -> str:
    code = ord(match.group())
    return f"\\x{code:02x}" if code < 0x100 else f"\\u{code:04x}"


def escaped(text) -> str:
    """``text`` (made a string) with every control character spelled as an escape."""
    return _CONTROL.sub(_visible, str(text))


# --------------------------------------------------------------------------- Markdown

#: Punctuation that acts inside a line: backslash escapes, code spans, emphasis, links and
#: images, raw HTML and autolinks, entity references, strike-through, and GitHub's math.
_MD_ACTIVE = re.compile(r"([\\`*_\[\]<>&~$!])")
#: ... and at the start of a line: headings, list items, block quotes, setext underlines.
_MD_LINE_START = re.compile(r"^([#+\-=>|])")
#: ... and GitHub's extended autolinks of ``www.`` and ``scheme://`` text, which its
#: renderer finds after the other escapes are resolved; a backslash before their dot or
#: colon stops it. (An e-mail address still becomes a ``mailto:`` link.)
_MD_AUTOLINK = re.compile(r"(?i)(?<![a-z0-9])(www)\.|:(?=//)")
_BACKTICKS = re.compile(r"`+")


def markdown_text(value) -> str:
    """``value`` as Markdown that renders as itself, in a sentence or a table cell.

    Every ASCII punctuation mark that Markdown acts on inside a line gets a backslash
    (which renders as nothing), and so does one that would start a block at the
    beginning of the text.

    >>> markdown_text('<img src=x onerror=alert(1)> [x](javascript:y)')
    '\\\\<img src=x onerror=alert(1)\\\\> \\\\[x\\\\](javascript:y)'
    """
    text = _MD_ACTIVE.sub(r"\\\1", escaped(value))
    text = _MD_AUTOLINK.sub(lambda m: f"{m.group(1)}\\." if m.group(1) else "\\:", text)
    return _MD_LINE_START.sub(r"\\\1", text)


def markdown_code(value) -> str:
    """``value`` as a Markdown code span that renders as itself ('' for an empty value).

    Backslashes do not escape inside a span, so it is fenced with one backtick more than
    the longest run of backticks inside it.

    >>> markdown_code("raw"), markdown_code("a`b")
    ('`raw`', '``a`b``')
    """
    text = escaped(value)
    if not text:
        return ""
    fence = "`" * (1 + max((len(run) for run in _BACKTICKS.findall(text)), default=0))
    # a span that starts or ends with a backtick, or with a space at both ends, loses its
    # first and last space: pad it with one each
    pad = " " if text[0] == "`" or text[-1] == "`" or (text[0] == text[-1] == " " and text.strip()) else ""
    return f"{fence}{pad}{text}{pad}{fence}"


# --------------------------------------------------------------------------- CSV

#: The first characters that make a spreadsheet (Excel, LibreOffice, Google Sheets) read a
#: cell as a formula, or that it drops before doing so (tab, CR, LF: OWASP, "CSV
#: Injection"), and the quote that marks a neutralised cell, so that a cell which starts
#: with a quote of its own reads back unchanged.
CSV_ACTIVE = ("=", "+", "-", "@", "\t", "\r", "\n", "'")


def csv_text(value) -> str:
    """A text cell as a CSV file holds it: ``value`` with a ``'`` before it when it starts
    with one of :data:`CSV_ACTIVE`, which a spreadsheet shows as text (and hides). A
    number's cell is never given here: ``-0.5`` stays a number. :func:`csv_read` undoes it.

    >>> csv_text('=HYPERLINK("http://e","x")'), csv_text("raw"), csv_read(csv_text("'q"))
    ('\\'=HYPERLINK("http://e","x")', 'raw', "'q")
    """
    text = str(value)
    return f"'{text}" if text[:1] in CSV_ACTIVE else text


def csv_read(cell: str) -> str:
    """The text of a cell :func:`csv_text` wrote (one leading ``'`` dropped)."""
    return cell[1:] if cell[:1] == "'" else cell
