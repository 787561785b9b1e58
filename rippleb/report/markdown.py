"""Markdown cells and tables: what every table of the report, and Table I, is written with.

A cell or a sentence that holds text rippleb does not choose (a method's label or message,
a file's name, a value read from a run directory) gets it through
:func:`rippleb.printable.markdown_text` or :func:`~rippleb.printable.markdown_code`; what
reaches a table cell also has its ``|`` escaped here, by :func:`markdown`, the one place
that writes a table.
"""

from __future__ import annotations

import numpy as np

from rippleb.printable import escaped

def markdown(rows, headers) -> str:
    """A GitHub Markdown table; cells are printed as given, but for ``|``, escaped as ``\\|``
    (a scenario file ``a|b.toml`` would otherwise split its cell in two). A cell that holds
    untrusted text is given through :func:`~rippleb.printable.markdown_text` or
    :func:`~rippleb.printable.markdown_code`."""
    from tabulate import tabulate

    rows = [[escape_cell(c) for c in row] for row in rows]
    return tabulate(rows, headers=[escape_cell(h) for h in headers], tablefmt="github", disable_numparse=True)


def escape_cell(value):
    """A table cell with every ``|`` escaped for Markdown (other values unchanged)."""
    return value.replace("|", "\\|") if isinstance(value, str) else value


def plural(n: int, word: str) -> str:
    return f"{n} {word}{'' if n == 1 else 's'}"


def first_line(message) -> str:
    text = "" if message is None or (isinstance(message, float) and np.isnan(message)) else str(message)
    return escaped(text.splitlines()[0]) if text.strip() else "(no message)"


def one_line(message) -> str:
    text = "" if message is None or (isinstance(message, float) and np.isnan(message)) else str(message)
    return escaped(text.splitlines()[0])[:200].replace("|", "/") if text else ""
