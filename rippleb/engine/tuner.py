"""``rippleb tune``'s work: every point of every method scored on the calibration logs.

The protocol is :mod:`rippleb.tuning` (ranges, points, rule); this module runs it. Each
tuning device's ``calibration`` log is simulated once per process; each candidate point
is fitted and run on each log (:func:`scores`) and scored against ``torque_ref``, never
``torque_true``, never a scored scenario. Points run in parallel on ``jobs`` processes;
the record is written after each method, so an interrupted tuning keeps what finished.
"""

from __future__ import annotations

import concurrent.futures
import multiprocessing
import time

import numpy as np

from rippleb.errors import PluginError
from rippleb.scoring.metrics import Truth
from rippleb.scoring.row import score_row
from rippleb.registry import Registry
from rippleb.simulator import simulate
from rippleb.harness import run_method
from rippleb.tuning import best_of, candidates, check_tunable, replaces_default

#: What a method without a ``tunable`` attribute is recorded with.
UNDECLARED = "declares no tunable ranges (scored at its defaults only)"
#: ... and one with ``tunable = {}``.
NOTHING = "declares nothing to tune (scored at its defaults only)"


def calibration_logs(seeds):
    """The calibration simulation of each seed, simulated once."""
    return [simulate("calibration", seed) for seed in seeds]


def mean_score(cls, params: dict, sims) -> dict:
    """Mean of each score column of ``cls(**params)`` fitted and run on each calibration log."""
    rows = [_score_row(cls, params, s) for s in sims]
    return {k: float(np.mean([r[k] for r in rows])) for k, v in rows[0].items() if isinstance(v, (int, float))}


def scores(cls, params: dict, sims) -> list[float]:
    """``rms_error_ref_nm`` of ``cls(**params)`` on each calibration log."""
    return [float(_score_row(cls, params, s)["rms_error_ref_nm"]) for s in sims]


def _score_row(cls, params, sim) -> dict:
    """The row's columns (:func:`rippleb.scoring.row.score_row`); ValueError naming why when
    its estimate cannot be scored."""
    estimate, ticks = run_method(cls(**params), sim.log, sim.log)
    row = score_row({"estimate": estimate, "ticks": ticks}, Truth.from_simulation(sim), len(estimate), len(ticks))
    if row["status"] != "ok":
        raise ValueError(f"{row['status']}: {row['message']}")
    return row


# ------------------------------------------------------------------ worker processes
_SIMS: list = []
_REGISTRY: Registry | None = None


def _start_worker(seeds) -> None:
    global _SIMS, _REGISTRY
    _SIMS, _REGISTRY = calibration_logs(seeds), Registry.discover()


def _evaluate(name: str, params: dict) -> tuple[list[float], str]:
    """One point's scores on every tuning device, or infinities and the error as one line."""
    try:
        return scores(_REGISTRY.get(name).load(), params, _SIMS), ""
    except Exception as exc:  # noqa: BLE001 - a method may raise anything; the point loses
        return [float("inf")] * len(_SIMS), f"{type(exc).__name__}: {exc}".splitlines()[0]


# ------------------------------------------------------------------ the protocol
def plan(names, registry: Registry, budget: int) -> dict[str, tuple[dict, list[dict], str]]:
    """Per method: its ranges, its candidate points and a note (no ranges, nothing to tune)."""
    out = {}
    for name in names:
        cls = registry.get(name).load()
        tunable = getattr(cls, "tunable", None)
        note = UNDECLARED if tunable is None else (NOTHING if not tunable else "")
        tunable = tunable or {}
        try:
            check_tunable(name, tunable)
            defaults = cls().get_params()
            missing = sorted(set(tunable) - set(defaults))
            if missing:
                raise ValueError(f"{name}.tunable names {', '.join(missing)}, which get_params() does not return")
        except Exception as exc:  # noqa: BLE001 - a plugin's class may raise anything
            raise PluginError(f"cannot tune {name!r}: {type(exc).__name__}: {exc}".splitlines()[0]) from None
        out[name] = (tunable, candidates(tunable, defaults, budget), note)
    return out


def tune(planned: dict, seeds, jobs: int = 1, on_method=None, on_point=None) -> dict:
    """Run the :func:`plan` ``planned`` on the calibration logs of ``seeds``; returns
    ``{name: entry}`` (see docs/tuning.md).

    ``on_method(name, entry)`` is called as each method finishes (to write the record),
    ``on_point()`` after each evaluation (a progress bar).
    """
    context = multiprocessing.get_context("spawn")  # no forked numba or BLAS threads
    results = {}
    with concurrent.futures.ProcessPoolExecutor(max_workers=max(1, jobs), mp_context=context,
                                                initializer=_start_worker, initargs=(list(seeds),)) as pool:
        futures = {name: [pool.submit(_evaluate, name, p) for p in points]
                   for name, (_, points, _) in planned.items()}
        for name, (tunable, points, note) in planned.items():
            start = time.perf_counter()
            tried = []
            for params, future in zip(points, futures[name]):
                tried.append((params, *future.result()))
                if on_point:
                    on_point()
            results[name] = entry(tunable, tried, note, time.perf_counter() - start)
            if on_method:
                on_method(name, results[name])
    return results


def entry(tunable: dict, tried: list[tuple[dict, list[float], str]], note: str, seconds: float) -> dict:
    """One method's record: every point with its scores, the best, the rule's verdict."""
    best = best_of([s for _, s, _ in tried])
    default, chosen = tried[0], tried[best]
    replaced = best != 0 and replaces_default(default[1], chosen[1])
    errors = sorted({e for _, _, e in tried if e})
    return {"tunable": {k: list(v) for k, v in tunable.items()}, "note": note,
            "default": default[0], "default_scores": default[1], "default_score": float(np.mean(default[1])),
            "best": chosen[0], "best_scores": chosen[1], "best_score": float(np.mean(chosen[1])),
            "replaced": replaced, "adopted": chosen[0] if replaced else default[0],
            "evaluations": len(tried), "seconds": round(seconds, 1), "errors": errors,
            "points": [{"params": p, "scores": s} for p, s, _ in tried]}
