"""The report's "How each method was tuned": the tuning record a run's provenance carries.

``rippleb run`` records :func:`rippleb.tuning.summary` (the protocol and, per built-in,
the point adopted as its defaults) in ``provenance.json``; this module prints it for the
methods of the report. Every value is the record's; a row's ``params`` column says what
that row actually ran (a variant ``NAME[p=v]`` runs other values).
"""

from __future__ import annotations

from rippleb.report.markdown import markdown
from rippleb.tuning import EVERY_DEVICE, rule_of


def tuning_markdown(tuning: dict | None, methods) -> str:
    """The protocol in one paragraph and one table row per method of the report."""
    intro, table = tuning_parts(tuning, methods)
    return "\n".join([intro, "", table]) if table else intro


def tuning_parts(tuning: dict | None, methods) -> tuple[str, str]:
    """The paragraph on the protocol, and the Markdown table ('' when nothing is recorded)."""
    if not tuning or "protocol" not in tuning:
        reason = (tuning or {}).get("error", "the run's provenance has no tuning record (an older run)")
        return f"Not recorded: {reason}.", ""
    protocol, record = tuning["protocol"], tuning["methods"]
    seeds = protocol["seeds"]
    intro = (f"One protocol for every built-in (`docs/tuning.md` in the repository): "
             f"a budget of {protocol['budget']} calibration evaluations per method, on the "
             f"`calibration` scenario of the tuning devices (seeds {seeds[0]}-{seeds[-1]}), never on a "
             f"scored scenario. Points: {protocol['sampler']}. Score: {protocol['criterion']}. "
             f"Rule: {protocol['rule']}. Record `methods/tuning.json`, sha256 "
             f"`{tuning.get('sha256', '?')[:16]}...`.")
    rows = []
    for name in methods:
        entry = record.get(name)
        if "[" in name:
            rows.append([f"`{name}`", "a variant: the values in its label, the rest as its method's", "-", "-", "-"])
            continue
        if entry is None:
            rows.append([f"`{name}`", "not in the built-ins' record (a plugin, or tuned elsewhere)", "-", "-", "-"])
            continue
        adopted = ", ".join(f"`{k}` = {v:g}" for k, v in (entry.get("adopted") or {}).items()) or "-"
        if entry.get("evaluations", 0) <= 1:
            verdict = entry.get("note") or "nothing to tune"
        elif entry.get("replaced"):
            verdict = ("the best point replaced the default" if entry.get("adopted") == (entry.get("best") or entry.get("adopted"))
                       else "a point that passed the paired test replaced the default")
        else:
            verdict = ("default kept (no point better on every device)" if rule_of(tuning) == EVERY_DEVICE
                       else "default kept (no point beat it by the paired test)")
        rows.append([f"`{name}`", verdict, adopted, _nm(entry.get("default_score")), _nm(entry.get("best_score"))])
    return intro, markdown(rows, ["method", "tuning", "values used", "score at the former default [Nm]",
                                  "best point's score [Nm]"])


def _nm(value) -> str:
    return "-" if value is None else f"{value:.3f}"
