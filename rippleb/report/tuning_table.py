"""The report's "How each method was tuned": the tuning record a run's provenance carries.

``rippleb run`` records :func:`rippleb.tuning.summary` (the protocol and, per built-in,
the point adopted as its defaults) in ``provenance.json``; this module prints it for the
methods of the report. Every value is the record's; a row's ``params`` column says what
that row actually ran (a variant ``NAME[p=v]`` runs other values).
"""

from __future__ import annotations

from rippleb.printable import markdown_code as code, markdown_text as text
from rippleb.report.markdown import markdown
from rippleb.tuning import EVERY_DEVICE, rule_of


def tuning_markdown(tuning: dict | None, methods) -> str:
    """The protocol in one paragraph and one table row per method of the report."""
    intro, table = tuning_parts(tuning, methods)
    return "\n".join([intro, "", table]) if table else intro


def tuning_parts(tuning: dict | None, methods) -> tuple[str, str]:
    """The paragraph on the protocol, and the Markdown table ('' when nothing is recorded).
    The record comes from the run's provenance.json: every value of it is written as text."""
    if not isinstance(tuning, dict) or not isinstance(tuning.get("protocol"), dict) \
            or not isinstance(tuning.get("methods"), dict):
        reason = (tuning if isinstance(tuning, dict) else {}).get(
            "error", "the run's provenance has no tuning record (an older run)")
        return f"Not recorded: {text(reason)}.", ""
    protocol, record = tuning["protocol"], tuning["methods"]
    seeds = protocol.get("seeds") if isinstance(protocol.get("seeds"), list) and protocol.get("seeds") else ["?"]
    intro = (f"One protocol for every built-in (`docs/tuning.md` in the repository): "
             f"a budget of {text(protocol.get('budget'))} calibration evaluations per method, on the "
             f"`calibration` scenario of the tuning devices (seeds {text(seeds[0])}-{text(seeds[-1])}), never "
             f"on a scored scenario. Points: {text(protocol.get('sampler'))}. Score: "
             f"{text(protocol.get('criterion'))}. Rule: {text(protocol.get('rule'))}. Record "
             f"`methods/tuning.json`, sha256 {code(str(tuning.get('sha256', '?'))[:16] + '...')}.")
    rows = []
    for name in methods:
        entry = record.get(name)
        if "[" in name:
            rows.append([code(name), "a variant: the values in its label, the rest as its method's", "-", "-", "-"])
            continue
        if not isinstance(entry, dict):
            rows.append([code(name), "not in the built-ins' record (a plugin, or tuned elsewhere)", "-", "-", "-"])
            continue
        adopted = entry.get("adopted") if isinstance(entry.get("adopted"), dict) else {}
        adopted = ", ".join(f"{code(k)} = {_g(v)}" for k, v in adopted.items()) or "-"
        if not isinstance(entry.get("evaluations", 0), (int, float)) or entry.get("evaluations", 0) <= 1:
            verdict = text(entry.get("note") or "nothing to tune")
        elif entry.get("replaced"):
            verdict = ("the best point replaced the default" if entry.get("adopted") == (entry.get("best") or entry.get("adopted"))
                       else "a point that passed the paired test replaced the default")
        else:
            verdict = ("default kept (no point better on every device)" if rule_of(tuning) == EVERY_DEVICE
                       else "default kept (no point beat it by the paired test)")
        rows.append([code(name), verdict, adopted, _nm(entry.get("default_score")), _nm(entry.get("best_score"))])
    return intro, markdown(rows, ["method", "tuning", "values used", "score at the former default [Nm]",
                                  "best point's score [Nm]"])


def _nm(value) -> str:
    return "-" if value is None else _number(value, ".3f")


def _g(value) -> str:
    return _number(value, "g")


def _number(value, spec: str) -> str:
    """A recorded number formatted, or, if it is not one, the recorded value as text."""
    try:
        return format(float(value), spec)
    except (TypeError, ValueError):
        return text(value)
