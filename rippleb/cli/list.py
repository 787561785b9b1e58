"""``rippleb list``: every method, scenario and deployment condition, one line each.

The parser (:mod:`rippleb.cli.program`) calls :func:`add_list`.
Plugins are imported only in isolated children (:func:`probe_plugins`), each under a timeout.
"""

from __future__ import annotations

from rippleb.cli.options import limit
from rippleb.errors import RipplebError
from rippleb.printable import escaped
from rippleb.method import first_line

PLUGIN_IMPORT_TIMEOUT_S = 20.0


def add_list(sub) -> None:
    p = sub.add_parser("list", help="list methods, scenarios and deployment conditions, one line each",
                       description="List every method with its origin (builtin, plugin, or broken "
                                   "with its import error) and what it does (its description, else "
                                   "the first line of its class or module docstring), every built-in scenario with whether it is scored and "
                                   "what it tests (the first sentence of its description), the "
                                   "deployment conditions, and the strain-gauge layouts with their "
                                   "gauges, channels, the orders they cancel and their sources. Plugins "
                                   "are imported in a child process, each under a timeout.")
    p.add_argument("--import-timeout", type=float, default=PLUGIN_IMPORT_TIMEOUT_S, metavar="S",
                   help=f"seconds a plugin may take to import (default {PLUGIN_IMPORT_TIMEOUT_S:g})")
    p.set_defaults(func=cmd_list)


#: ``rippleb list`` fits a terminal this wide; longer descriptions wrap.
LIST_WIDTH = 100


def cmd_list(args) -> int:
    """``rippleb list``."""
    from rippleb.layouts import LAYOUT_NAMES, cancelled_orders, layout
    from rippleb.registry import Registry
    from rippleb.simulator.scenario import builtin_scenarios, load_scenario
    from rippleb.simulator.conditions import CONDITIONS

    registry = Registry.discover()
    timeout = limit("--import-timeout", args.import_timeout) or None
    errors, docs = probe_plugins(registry, timeout)
    print("methods:")
    for name in registry.names():
        entry = registry.entries[name]
        error = entry.error or errors.get(name)
        if error:
            print(f"  {name:<28} {'broken':<10} {entry.source}  {escaped(error)}")
            continue
        # a built-in's docstring is read from its source: importing every method family
        # (numba kernels compiled on a fresh install) would make `list` take seconds
        about = (entry.description or first_line(entry.doc)) if entry.origin == "builtin" \
            else docs.get(name, "")
        print(_fit(f"  {name:<28} {entry.origin:<10} {escaped(about or entry.source)}"))
    for module, error in sorted(registry.broken_modules.items()):
        print(f"  {'?':<28} {'broken':<8} {module}  {escaped(error)}")
    print("scenarios:")
    for name in builtin_scenarios():
        try:
            scenario = load_scenario(name)
        except RipplebError as exc:
            print(f"  {name:<28} broken      {escaped(exc)}")
            continue
        scored = "scored" if scenario.scored else "not scored"
        print(_fit(f"  {name:<28} {scored:<10} {first_sentence(scenario.description)}"))
    print("conditions (what happened between calibration and scoring):")
    for name, text in CONDITIONS.items():
        print(_fit(f"  {name:<28} {'':<10} {text}"))
    print("gauge layouts ([gauges] layout = NAME in a scenario; gauges x amplifier channels):")
    for name in LAYOUT_NAMES:
        lay = layout(name)
        cancelled = cancelled_orders(lay, LISTED_ORDERS)
        cancels = f"cancels orders {', '.join(map(str, cancelled))}; " if cancelled else ""
        print(_fit(f"  {name:<28} {f'{lay.gauges} x {lay.amplifiers}':<10} {lay.summary}; {cancels}"
                   f"{lay.source}"))
    return 0


#: The orders of the wave-generator angle ``rippleb list`` says a layout cancels.
LISTED_ORDERS = (1, 2, 3, 4, 5, 6, 7, 8)


#: Words ending in a full stop that do not end a sentence.
_ABBREVIATIONS = ("Fig", "Figs", "Sec", "Eq", "e.g", "i.e", "al", "approx", "cf")


def first_sentence(text: str) -> str:
    """The first sentence of ``text`` on one line (a full stop after an abbreviation such
    as "Fig." does not end it)."""
    import re

    flat = " ".join(text.split())
    for match in re.finditer(r"\.\s", flat):
        word = flat[: match.start()].rsplit(" ", 1)[-1]
        if word not in _ABBREVIATIONS:
            return flat[: match.start() + 1]
    return flat


def _fit(line: str) -> str:
    """``line`` wrapped at :data:`LIST_WIDTH`, continuation lines under the description."""
    import textwrap

    indent = " " * 42  # under the description: 2 + 28 + 1 + 10 + 1
    return textwrap.fill(line, LIST_WIDTH, subsequent_indent=indent, break_on_hyphens=False)


def probe_plugins(registry, timeout: float) -> tuple[dict[str, str], dict[str, str]]:
    """Import every plugin in its own isolated child, under ``timeout`` seconds each;
    return ``{name: one-line error}`` of those that failed and ``{name: summary}``
    (:meth:`rippleb.Method.summary`) of those that loaded."""
    from rippleb.engine.methods import probe

    plugins = [name for name in registry.names("plugin") if not registry.entries[name].broken]
    summaries, errors = probe(registry, plugins, lambda entry: entry.load().summary().encode(), timeout)
    errors = {name: error + " (--import-timeout)" if error.startswith("TimeoutError") else error
              for name, error in errors.items()}
    return errors, {name: text.decode(errors="replace") for name, text in summaries.items()}
