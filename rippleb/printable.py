"""Text from code rippleb does not trust, made safe to print and to write.

A method's error message, a plugin's import error or a cell of an edited results file may
hold control characters: an escape sequence that reaches a terminal can move its cursor,
rewrite lines already printed, retitle the window or, on some terminals, answer back; in
a README or a CSV a newline or carriage return forges a line. :func:`escaped` spells every
such character as a visible escape (``ESC`` becomes ``\\x1b``), so the text stays readable
and cannot act. It is applied where such text enters a row (the runner's results) and
again wherever rows or messages are printed or written (the CLI's lines, the report's
tables), so a results file edited by hand is no way around it.
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
