"""One look per method, the same in every figure of the report and of the HTML page.

Sixteen methods in one figure cannot be told apart by colour alone, so each has a colour,
a marker and a line dash, and no two share colour and marker. A family shares its colour and
differs in marker and dash (``order-tracking`` and its two ablations; ``angle-adaptive``,
its frozen map, ``gear-aware``, which fits that map, and ``gear-keeping``, which learns it
beside the gear's torque; ``gain-tuned``, hardware compensation, beside ``current-based``); the colours are the Okabe-Ito
palette, told apart by colour-blind readers too (Okabe & Ito, "Color Universal Design",
2008), without its yellow, which a white page washes out. A method not listed (a plugin)
gets the next unused colour and marker.

Markers and dashes are named as plotly names them; :func:`matplotlib_style` translates.
"""

from __future__ import annotations

import itertools

#: Okabe-Ito colours: black (torque_true's), orange, sky blue, bluish green, blue, vermillion,
#: reddish purple; and a grey for the baselines.
ORANGE, SKY, GREEN, BLUE, VERMILLION, PURPLE, GREY = ("#E69F00", "#56B4E9", "#009E73", "#0072B2",
                                                      "#D55E00", "#CC79A7", "#666666")
#: (colour, marker, dash) per built-in method.
LOOKS = {
    "raw": (GREY, "circle", "solid"), "lowpass": (GREY, "square", "dash"),
    "current-based": (PURPLE, "circle", "solid"),
    "order-tracking": (VERMILLION, "circle", "solid"), "order-tracking-no-deadzone": (VERMILLION, "square", "dash"),
    "order-tracking-no-backprop": (VERMILLION, "diamond", "dot"),
    "switched-notch": (GREEN, "circle", "solid"), "spatial-filter": (GREEN, "square", "dash"),
    "kalman-ripple": (ORANGE, "circle", "solid"), "fourier-lms": (SKY, "circle", "solid"),
    "periodic-dob": (SKY, "square", "dash"),
    "angle-adaptive": (BLUE, "circle", "solid"), "angle-adaptive-frozen": (BLUE, "square", "dash"),
    "gear-aware": (BLUE, "triangle-up", "dot"), "gear-keeping": (BLUE, "diamond", "dashdot"),
    "gain-tuned": (PURPLE, "square", "dash"),
}
_COLOURS = (ORANGE, SKY, GREEN, BLUE, VERMILLION, PURPLE, GREY)
_MARKERS = ("x", "star", "triangle-down", "cross", "hexagon", "pentagon")
_DASHES = ("dashdot", "longdash", "solid", "dash", "dot")
_MATPLOTLIB_MARKERS = {"circle": "o", "square": "s", "diamond": "D", "triangle-up": "^", "x": "x", "star": "*",
                       "triangle-down": "v", "cross": "P", "hexagon": "h", "pentagon": "p"}
_MATPLOTLIB_DASHES = {"solid": "-", "dash": "--", "dot": ":", "dashdot": "-.", "longdash": (0, (8, 3))}


def look(method: str, index: int = 0) -> tuple[str, str, str]:
    """``(colour, marker, dash)`` of ``method``; ``index``, its place among the methods shown,
    picks a look no built-in has for a method not listed."""
    if method in LOOKS:
        return LOOKS[method]
    spare = [combo for combo in itertools.product(_COLOURS, _MARKERS) if combo not in
             {(c, m) for c, m, _ in LOOKS.values()}]
    colour, marker = spare[index % len(spare)]
    return colour, marker, _DASHES[index % len(_DASHES)]


def matplotlib_style(method: str, index: int = 0) -> dict:
    """matplotlib keyword arguments of ``method``'s line: colour and dash (and its label)."""
    colour, _marker, dash = look(method, index)
    return {"color": colour, "ls": _MATPLOTLIB_DASHES[dash], "label": method}


def matplotlib_marker(method: str, index: int = 0) -> str:
    """matplotlib's name of ``method``'s marker (for its points)."""
    return _MATPLOTLIB_MARKERS[look(method, index)[1]]
