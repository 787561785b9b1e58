"""``rippleb tune``'s work: every point of every method scored on the calibration logs.

The protocol is :mod:`rippleb.tuning` (ranges, points, rule); this module runs it, and runs
it as a run runs its rows (issue 41, item 1): each point on each tuning device is a row of
the scheduler (:mod:`rippleb.engine.scheduler`), its fit and steps in the sandboxed worker of
a method (:mod:`rippleb.engine.process`), under the run's time and memory limits. The
calibration log of each device is simulated once, by rippleb's own job: the point's method
is fitted on it as a method may see it (with ``torque_ref``), run on it without either
reference, and scored in the runner against ``torque_ref`` (never ``torque_true``, never a
scored scenario). No process that runs a method's code holds a truth, and none of this
process runs it: a method's declared ranges and defaults are read in its own sandboxed
worker too (:func:`plan`). A point that hangs, exits or fails its checks costs that point
(its score infinite, its reason in the record's errors); the record is written after each
method, so an interrupted tuning keeps what finished.
"""

from __future__ import annotations

import json
import time

import numpy as np

from rippleb.errors import PluginError
from rippleb.registry import Registry
from rippleb.tuning import PROTOCOL_RULE, adopted, best_of, candidates, check_tunable, pvalues
from rippleb.variants import label

#: What a method without a ``tunable`` attribute is recorded with.
UNDECLARED = "declares no tunable ranges (scored at its defaults only)"
#: ... and one with ``tunable = {}``.
NOTHING = "declares nothing to tune (scored at its defaults only)"
#: The column a point is scored by (rippleb.tuning.CRITERION).
CRITERION_COLUMN = "rms_error_ref_nm"


def plan(names, registry: Registry, budget: int, timeout: float | None = None) -> dict[str, tuple[dict, list[dict], str]]:
    """Per method: its ranges, its candidate points and a note (no ranges, nothing to tune).

    Each method's ``tunable`` and defaults are read in its own sandboxed worker
    (:func:`rippleb.engine.methods.probe`); a declaration that cannot be tuned is one
    :class:`~rippleb.errors.PluginError` line naming the method.
    """
    from rippleb.engine.methods import SIGNATURE_TIMEOUT_S, probe

    declared, errors = probe(registry, list(names), _declaration, SIGNATURE_TIMEOUT_S if timeout is None else timeout)
    out = {}
    for name in names:
        if name in errors:
            raise PluginError(f"cannot tune {name!r}: {errors[name]}".splitlines()[0])
        found = json.loads(declared[name])
        tunable = {k: tuple(v) for k, v in found["tunable"].items()}
        out[name] = (tunable, candidates(tunable, found["defaults"], budget), found["note"])
    return out


def _declaration(entry) -> bytes:
    """In the method's worker: its checked ``tunable`` ranges, its defaults of them and the
    note, as JSON; a declaration that cannot be tuned raises, naming why."""
    cls = entry.load()
    tunable = getattr(cls, "tunable", None)
    note = UNDECLARED if tunable is None else (NOTHING if not tunable else "")
    tunable = tunable or {}
    check_tunable(entry.name, tunable)
    defaults = cls().get_params()
    missing = sorted(set(tunable) - set(defaults))
    if missing:
        raise ValueError(f"{entry.name}.tunable names {', '.join(missing)}, which get_params() does not return")
    return json.dumps({"tunable": tunable, "defaults": {p: defaults[p] for p in tunable}, "note": note}).encode()


def tune(planned: dict, seeds, jobs: int = 1, on_method=None, on_point=None, timeout: float | None = None,
         memory_mb: float | None = None, registry: Registry | None = None, rule: str = PROTOCOL_RULE) -> dict:
    """Run the :func:`plan` ``planned`` on the calibration logs of ``seeds``; returns
    ``{name: entry}`` (see docs/tuning.md).

    ``on_method(name, entry)`` is called as each method finishes (to write the record),
    ``on_point()`` after each evaluation (a progress bar); ``timeout`` and ``memory_mb``
    are a row's limits (:func:`rippleb.engine.runner.run`'s defaults when None); ``rule``
    the adoption rule (:data:`rippleb.tuning.RULES`).
    """
    from rippleb.engine.runner import DEFAULT_MEMORY_MB, DEFAULT_TIMEOUT_S, run_plan

    seeds = list(seeds)
    labels = {name: [label(name, p) for p in tried] for name, (_, tried, _) in planned.items()}
    owner = {lab: name for name, labs in labels.items() for lab in labs}
    rows_left = {lab: len(seeds) for lab in owner}          # a point is done on every device
    points_left = {name: len(set(labs)) for name, labs in labels.items()}
    scores: dict = {}
    results, start = {}, time.perf_counter()

    def recorded(row) -> None:
        lab = row["method"]
        scores[(lab, int(row["seed"]))] = _score(row)
        rows_left[lab] -= 1
        if rows_left[lab]:
            return
        name = owner[lab]
        points_left[name] -= 1
        if on_point:
            on_point()
        if not points_left[name]:
            tunable, tried, note = planned[name]
            found = [(p, *_per_device([scores[(lab, s)] for s in seeds])) for lab, p in zip(labels[name], tried)]
            results[name] = entry(tunable, found, note, time.perf_counter() - start, rule)
            if on_method:
                on_method(name, results[name])

    run_plan(registry or Registry.discover(), tuning_plan(list(owner), seeds), jobs=jobs,
             timeout=DEFAULT_TIMEOUT_S if timeout is None else timeout,
             memory_mb=DEFAULT_MEMORY_MB if memory_mb is None else memory_mb, on_record=recorded)
    return {name: results[name] for name in planned}


def tuning_plan(labels: list[str], seeds):
    """The rows of a tuning: each variant label on each tuning device, fitted on that
    device's calibration log and scored on the same session (one simulation, both roles)."""
    from rippleb.engine.rows import CALIBRATION, FITTING, SCORED, Case, RowKey, scenario_hash
    from rippleb.engine.plan import Plan
    from rippleb.simulator.scenario import load_scenario
    from rippleb.simulator.conditions import DEFAULT_CONDITION

    calibration = load_scenario(CALIBRATION)
    content = scenario_hash(calibration)
    plan = Plan(calibration_label=CALIBRATION)
    cases = {seed: [Case(CALIBRATION, content, DEFAULT_CONDITION, seed, role) for role in (FITTING, SCORED)]
             for seed in seeds}
    for fitting, scored in cases.values():
        plan.add_sim(calibration, fitting)
        plan.add_sim(calibration, scored)
    # method by method (the scheduler starts rows in this order): each method's entry is
    # recorded as soon as its points are done on every device, so a tuning cut short keeps
    # the methods it finished (``rippleb tune --out`` goes on from them)
    for lab in labels:
        for seed, (fitting, scored) in cases.items():
            plan.add_row(RowKey(lab, CALIBRATION, DEFAULT_CONDITION, seed), scored, fitting)
    return plan


def _score(row: dict) -> tuple[float, str]:
    """A point's score on one device and, where it has none, why (its status and message)."""
    value = row.get(CRITERION_COLUMN)
    if row.get("status") == "ok" and value is not None and np.isfinite(value):
        return float(value), ""
    return float("inf"), f"{row.get('status')}: {row.get('message', '')}".splitlines()[0][:300]


def _per_device(found: list[tuple[float, str]]) -> tuple[list[float], str]:
    """One point's scores on every device and its first error ('' if none)."""
    return [s for s, _ in found], next((e for _, e in found if e), "")


def entry(tunable: dict, tried: list[tuple[dict, list[float], str]], note: str, seconds: float,
          rule: str = PROTOCOL_RULE) -> dict:
    """One method's record: every point with its scores, the best, ``rule``'s verdict."""
    scores = [s for _, s, _ in tried]
    best, kept = best_of(scores), adopted(scores, rule)
    default, chosen = tried[0], tried[best]
    replaced = kept != 0
    errors = sorted({e for _, _, e in tried if e})
    return {"tunable": {k: list(v) for k, v in tunable.items()}, "note": note,
            "default": default[0], "default_scores": default[1], "default_score": float(np.mean(default[1])),
            "best": chosen[0], "best_scores": chosen[1], "best_score": float(np.mean(chosen[1])),
            "replaced": replaced, "adopted": tried[kept][0], "adopted_scores": tried[kept][1],
            "evaluations": len(tried), "seconds": round(seconds, 1), "errors": errors,
            "points": [{"params": p, "scores": s, "p_holm": q if np.isfinite(q) else None}
                       for (p, s, _), q in zip(tried, pvalues(scores))]}
