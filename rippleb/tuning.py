"""One tuning protocol for every method: its declared ranges, one sampler, one budget, one rule.

A method declares the constructor parameters worth tuning and their ranges as a class
attribute ``tunable = {"param": (low, high, "log" | "linear" | "int"), ...}`` (``{}``:
nothing to tune, e.g. a method whose parameters come from its sources or are fitted on
the calibration log). :func:`candidates` turns a declaration into the same number of
points for every method: the default, then ``budget - 1`` points of a scrambled Sobol
sequence (``scipy.stats.qmc``, seeded, so the points re-run) mapped onto the ranges and
rounded to three significant digits (a value a page can quote and a constructor default
can hold exactly). ``rippleb tune`` (:mod:`rippleb.engine.tuner`) scores each point on
the ``calibration`` scenario only, against its ``torque_ref`` (the only torque a real
calibration knows), on every tuning device; :func:`adopted` is the rule that decides
which point, if any, replaces the default: a paired test over the tuning devices
(:mod:`rippleb.signed_rank`), not the mean alone, so that a point that wins by the noise
of a few devices does not move a method. The record of the built-ins' tuning
ships beside them (:data:`RECORD`, ``methods/tuning.json``, written by ``rippleb tune``);
the built-ins' defaults are its adopted points (``tests/test_tuning.py``), and every run's
provenance carries its :func:`summary`. docs/tuning.md says what it found.

Examples
--------
>>> points = candidates({"q": (1.0, 100.0, "log")}, {"q": 30.0}, budget=4)
>>> len(points), points[0]
(4, {'q': 30.0})
>>> default = [1.0 + 0.01 * k for k in range(10)]
>>> adopted([default, [d - 0.05 for d in default], [d + 0.01 for d in default]])
1
"""

from __future__ import annotations

import hashlib
import json
from importlib import resources

import numpy as np

from rippleb.signed_rank import ALPHA, holm, signed_rank

KINDS = ("log", "linear", "int")
#: The seed of the Sobol scrambling: every method sees the same sequence of unit points.
SEED = 33
#: Calibration evaluations per method (the default and 15 Sobol points); docs/tuning.md.
BUDGET = 16
#: The paired rule's tuning devices, one calibration log each: 20 public seeds that no
#: development check uses (those are 0-99) and no publication can (its devices are drawn from
#: a sealed salt); 20, so that the signed-rank test can pass after Holm over 15 points.
PAIRED_SEEDS = tuple(range(100, 120))
#: The devices of the built-ins' record (``methods/tuning.json``) and ``rippleb tune``'s
#: default: :data:`PAIRED_SEEDS` (the former rule's record used their first five).
SEEDS = PAIRED_SEEDS
CRITERION = ("mean rms_error_ref_nm (against torque_ref) of the method fitted on the calibration "
             "log of each tuning device and run on that same log")
#: The rule, by name (a record keeps it in ``protocol.rule_id``) and in words.
RULE_ID = "holm-signed-rank"
RULE = ("a point replaces the default only when the one-sided Wilcoxon signed-rank test of its "
        "per-device differences from the default says it is lower, at 5 % after Holm's correction over "
        "the budget-1 points tried; of the points that pass, the one of lowest mean; otherwise the "
        "default stays")
#: The former rule (records made before :data:`RULE_ID` name none): the point of lowest
#: mean, only when better on every tuning device.
EVERY_DEVICE = "every-device"
EVERY_DEVICE_RULE = ("the point of lowest mean replaces the default only when it is better on every tuning "
                     "device (paired); otherwise the default stays")
#: The rules ``rippleb tune --rule`` runs, by name, in words.
RULES = {RULE_ID: RULE, EVERY_DEVICE: EVERY_DEVICE_RULE}
#: The rule of the built-ins' record, ``rippleb tune``'s default: the paired rule, under which
#: every built-in was re-tuned on :data:`PAIRED_SEEDS` (2026-11-27, docs/tuning.md).
PROTOCOL_RULE = RULE_ID
#: The record of the built-ins' tuning, in the methods package.
RECORD = "tuning.json"


def check_tunable(name: str, tunable: dict) -> None:
    """Refuse a malformed ``tunable`` declaration with one line naming the method."""
    if not isinstance(tunable, dict):
        raise ValueError(f"{name}.tunable must be a dict of ranges, got {type(tunable).__name__}")
    for param, spec in tunable.items():
        if not (isinstance(spec, tuple) and len(spec) == 3 and spec[2] in KINDS and spec[0] < spec[1]):
            raise ValueError(f"{name}.tunable[{param!r}] must be (low, high, one of {KINDS}) with low < high, "
                             f"got {spec!r}")
        if spec[2] == "log" and spec[0] <= 0:
            raise ValueError(f"{name}.tunable[{param!r}]: a log range must be positive, got {spec!r}")


def candidates(tunable: dict, defaults: dict, budget: int) -> list[dict]:
    """``budget`` parameter sets: ``defaults`` first, then Sobol points over ``tunable``."""
    if budget < 1:
        raise ValueError(f"budget must be at least 1, got {budget}")
    first = {p: defaults[p] for p in tunable}
    if not tunable or budget == 1:
        return [first]
    from scipy.stats import qmc

    # the first budget - 1 points of a power-of-two Sobol block (scipy warns on other sizes)
    m = int(np.ceil(np.log2(budget - 1))) if budget > 2 else 0
    unit = qmc.Sobol(len(tunable), scramble=True, seed=SEED).random_base2(m)[:budget - 1]
    points = [first]
    for row in unit:
        points.append({p: _scale(u, *spec) for u, (p, spec) in zip(row, tunable.items())})
    return points


def _scale(u: float, low: float, high: float, kind: str):
    """A unit coordinate ``u`` in [0, 1) onto the range, three significant digits."""
    if kind == "int":
        return int(low + np.floor(u * (high - low + 1)))
    if kind == "log":
        value = float(np.exp(np.log(low) + u * (np.log(high) - np.log(low))))
    else:
        value = float(low + u * (high - low))
    return min(max(float(f"{value:.3g}"), low), high)


def adopted(scores, rule: str = RULE_ID) -> int:
    """The index of the point the rule adopts; 0 (the default) when none replaces it.

    ``scores[i]`` holds point ``i``'s score on each tuning device, ``scores[0]`` the
    default's. Under :data:`RULE_ID` a point must beat the default by :func:`pvalues`;
    under :data:`EVERY_DEVICE` (the former rule) the point of lowest mean must be lower on
    every device.
    """
    best = best_of(scores)
    if rule == EVERY_DEVICE:
        return best if best != 0 and replaces_default(scores[0], scores[best]) else 0
    if rule != RULE_ID:
        raise ValueError(f"unknown tuning rule {rule!r}")
    passing = [i for i, p in enumerate(pvalues(scores)) if i and p < ALPHA]
    return min(passing, key=lambda i: (float(np.mean(scores[i])), i)) if passing else 0


def pvalues(scores) -> list[float]:
    """Per point, the Holm-adjusted p-value of the one-sided signed-rank test that it is lower
    than the default on the tuning devices (NaN for the default itself; 1 for a point that
    failed on some device)."""
    default = np.asarray(scores[0], float)
    raw = []
    for point in scores[1:]:
        point = np.asarray(point, float)
        raw.append(signed_rank(default - point, "greater")[0] if np.all(np.isfinite(point)) else 1.0)
    return [float("nan")] + holm(raw)


def replaces_default(default_scores, best_scores) -> bool:
    """The former rule: the best point is better than the default on every tuning device."""
    default_scores, best_scores = np.asarray(default_scores), np.asarray(best_scores)
    return bool(len(best_scores) and np.all(best_scores < default_scores))


def best_of(scores: list[list[float]]) -> int:
    """Index of the point of lowest mean score over the devices (the earliest of equals);
    ``scores[0]`` is the default's."""
    return int(np.argmin([float(np.mean(s)) for s in scores]))


def rule_of(record: dict) -> str:
    """The rule a record was made by (records older than :data:`RULE_ID` name none)."""
    return record.get("protocol", {}).get("rule_id", EVERY_DEVICE)


def adopted_points(record, source: str) -> dict[str, dict]:
    """Per method of a tuning record (``rippleb tune --out FILE``): the point the rule adopted,
    for the methods whose best point replaced their default; an :class:`InputError` naming
    ``source`` and the field for a record that is not one."""
    from rippleb.errors import InputError

    methods = record.get("methods") if isinstance(record, dict) else None
    if not isinstance(methods, dict):
        raise InputError(f"{source}: not a tuning record of 'rippleb tune --out FILE' (no 'methods' table)")
    out = {}
    for name, entry in methods.items():
        adopted = entry.get("adopted") if isinstance(entry, dict) else None
        if not isinstance(adopted, dict) or not all(isinstance(k, str) and isinstance(v, (bool, int, float, str))
                                                    for k, v in adopted.items()):
            raise InputError(f"{source}: methods.{name}.adopted: expected a table of parameter values, got "
                             f"{str(adopted)[:60]}")
        if entry.get("replaced") and adopted:
            out[name] = adopted
    return out


def _record_text() -> str:
    return resources.files("rippleb.methods").joinpath(RECORD).read_text()


def read_record(text: str | None = None) -> dict:
    """The record of the built-ins' tuning (``methods/tuning.json``), or one given as text."""
    return json.loads(_record_text() if text is None else text)


def summary() -> dict:
    """What a run's provenance keeps of the built-ins' tuning: the protocol, each method's
    adopted point and whether it replaced the default, and the record's hash."""
    try:
        text = _record_text()
    except (OSError, ModuleNotFoundError) as exc:
        return {"error": f"no tuning record: {exc}"}
    record = read_record(text)
    return {"sha256": hashlib.sha256(text.encode()).hexdigest(), "protocol": record["protocol"],
            "methods": {name: {k: entry.get(k) for k in ("adopted", "best", "replaced", "evaluations",
                                                           "default_score", "best_score", "note")}
                        for name, entry in record["methods"].items()}}
