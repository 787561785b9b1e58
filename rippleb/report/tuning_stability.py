"""How much the tuning protocol's outcome depends on its devices: two disjoint sets compared.

``rippleb tune --seeds A --out a.json`` and ``--seeds B --out b.json`` run the one protocol
(:mod:`rippleb.tuning`) on two disjoint sets of tuning devices. Both records score the same
points (the default and the same Sobol points, :func:`rippleb.tuning.candidates`), so each
record can say how the other set's choice scores on its own devices: what it would have
cost to tune on the other set. ``rippleb tune --compare a.json b.json`` prints the table
(:func:`stability_markdown`) for the current rule and for the former one; docs/tuning.md
publishes it.

Examples
--------
>>> def record(seeds, shift):
...     default = [1.0 + 0.01 * k for k in range(8)]
...     point = [d + shift + 0.001 * k for k, d in enumerate(default)]
...     return {"protocol": {"seeds": seeds}, "methods": {"m": {"points": [
...         {"params": {"q": 1}, "scores": default}, {"params": {"q": 2}, "scores": point}]}}}
>>> row, = stability_rows(record(list(range(8)), -0.05), record(list(range(8, 16)), 0.02))
>>> row["adopted"], row["same"], [round(c, 4) for c in row["cost"]]
((1, 0), False, [0.0235, 0.0465])
"""

from __future__ import annotations

import numpy as np

from rippleb.errors import InputError
from rippleb.printable import markdown_code as code
from rippleb.report.markdown import markdown
from rippleb.tuning import EVERY_DEVICE, RULE_ID, adopted

#: The rules the table compares: the current one first.
RULES = (RULE_ID, EVERY_DEVICE)


def read(path) -> dict:
    """A tuning record written by ``rippleb tune --out``, read within the cap of a run's files
    (:mod:`rippleb.reading`); one line naming the file otherwise (missing, too large, not
    JSON, or without the fields the table reads: the seeds, and per method its points'
    params and scores)."""
    from rippleb.reading import RUN_FILE_BYTES, parse_json, read_text

    try:
        record = parse_json(read_text(path, RUN_FILE_BYTES, "tuning record"), path)
    except FileNotFoundError:
        raise InputError(f"{path}: no such tuning record") from None
    if not _is_record(record):
        raise InputError(f"{path}: not a tuning record written by 'rippleb tune --out' (it needs protocol.seeds "
                         f"and, per method, points with params and scores)")
    return record


def _is_record(record) -> bool:
    """Whether ``record`` has the fields :func:`stability_rows` reads, of the types it reads."""
    def number(v):
        return isinstance(v, (int, float)) and not isinstance(v, bool)

    def point(p):
        return (isinstance(p, dict) and isinstance(p.get("params"), dict) and isinstance(p.get("scores"), list)
                and all(number(v) for v in [*p["params"].values(), *p["scores"]]))

    protocol = record.get("protocol") if isinstance(record, dict) else None
    seeds = protocol.get("seeds") if isinstance(protocol, dict) else None
    methods = record.get("methods") if isinstance(record, dict) else None
    return (isinstance(seeds, list) and all(isinstance(s, int) for s in seeds) and isinstance(methods, dict)
            and all(isinstance(e, dict) and isinstance(e.get("points"), list) and e["points"]
                    and all(point(p) for p in e["points"]) for e in methods.values()))


def stability_rows(a: dict, b: dict, rule: str = RULE_ID) -> list[dict]:
    """Per method of both records: the point each set adopts under ``rule``, whether they
    are the same, and what each choice costs on the other set's devices.

    Returns
    -------
    list of dict
        ``method``, ``params`` (the points, in the records' order), ``adopted`` (the index
        each set adopts), ``same``, and ``cost`` (``a``'s choice on ``b``'s devices minus
        ``b``'s own, and the reverse: mean difference [Nm], positive when the other set's
        choice scores worse).
    """
    overlap = set(a["protocol"]["seeds"]) & set(b["protocol"]["seeds"])
    if overlap:
        raise InputError(f"the two tuning sets share devices {sorted(overlap)[:5]}: compare disjoint sets")
    rows = []
    for name in [m for m in a["methods"] if m in b["methods"]]:
        pa, pb = a["methods"][name]["points"], b["methods"][name]["points"]
        params = [p["params"] for p in pa]
        if params != [p["params"] for p in pb]:
            raise InputError(f"{name}: the two records tried different points (another budget, range or "
                             f"default): run both with the same code and --budget")
        sa, sb = [p["scores"] for p in pa], [p["scores"] for p in pb]
        ia, ib = adopted(sa, rule), adopted(sb, rule)
        rows.append({"method": name, "params": params, "adopted": (ia, ib), "same": ia == ib,
                     "cost": (float(np.mean(sb[ia]) - np.mean(sb[ib])), float(np.mean(sa[ib]) - np.mean(sa[ia])))})
    return rows


def _point(params: list[dict], index: int) -> str:
    if not params[index]:
        return "nothing to tune"
    values = ", ".join(f"{code(k)} = {v:g}" for k, v in params[index].items())
    return f"default ({values})" if index == 0 else values


def _seeds(record: dict) -> str:
    seeds = record["protocol"]["seeds"]
    if len(seeds) > 1 and seeds == list(range(seeds[0], seeds[-1] + 1)):
        return f"{seeds[0]}-{seeds[-1]}"
    return ",".join(map(str, seeds))


def stability_markdown(a: dict, b: dict) -> str:
    """The stability table of two records and one sentence per rule: which points each set
    adopts under the current rule, what each costs on the other set, and how often each
    rule adopts the same point on both sets."""
    sa, sb = _seeds(a), _seeds(b)
    rows = {rule: stability_rows(a, b, rule) for rule in RULES}
    former = {r["method"]: r for r in rows[EVERY_DEVICE]}
    table = []
    for r in rows[RULE_ID]:
        ia, ib = r["adopted"]
        old = former[r["method"]]
        table.append([code(r["method"]), _point(r["params"], ia), _point(r["params"], ib),
                      "yes" if r["same"] else "no", f"{r['cost'][0]:+.3f}", f"{r['cost'][1]:+.3f}",
                      f"{'replaced' if old['adopted'][0] else 'kept'} / {'replaced' if old['adopted'][1] else 'kept'}"
                      + ("" if old["same"] else " (differ)")])
    heads = ["method", f"adopted on devices {sa}", f"adopted on devices {sb}", "same point",
             f"{sa}'s point on {sb}'s devices, minus {sb}'s own [Nm]", f"{sb}'s point on {sa}'s devices, minus {sa}'s own [Nm]",
             f"former rule (better on every device): {sa} / {sb}"]
    tuned = {rule: [r for r in rows[rule] if len(r["params"]) > 1] for rule in RULES}
    sentences = []
    for rule, words in ((RULE_ID, "the paired test (Holm over the points)"),
                        (EVERY_DEVICE, "the former rule (better on every device)")):
        same = sum(r["same"] for r in tuned[rule])
        worst = max(tuned[rule], key=lambda r: max(r["cost"]), default=None)
        text = f"By {words}, {same} of {len(tuned[rule])} methods with something to tune adopt the same point on both sets"
        if worst is not None and max(worst["cost"]) > 0:
            text += (f"; tuning on the other set costs at most {max(worst['cost']):.3f} Nm of calibration score "
                     f"({code(worst['method'])})")
        sentences.append(text + ".")
    return markdown(table, heads) + "\n\n" + "\n".join(f"- {s}" for s in sentences)
