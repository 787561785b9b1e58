"""The jobs of a run as plain functions, so any executor can run them.

* :func:`simulate_case` runs the simulator (rippleb's code only) and splits its output
  into what a method may see (written to a hashed cache file) and the truth (returned,
  for the runner to keep in memory).
* :func:`fit_method` fits a method on a visible calibration log and pickles it.
* :func:`run_row` is the row job: ``(method name, params, visible calibration log or its
  artefact, visible evaluation log or its artefact[, fitted artefact]) -> (fit info,
  estimate, tick times)``. It never receives the truth; the runner scores the estimate.

Artefacts are verified (:class:`rippleb.engine.cache.Artefact`) *before* the method's code is
imported, so a method cannot rewrite an input between verification and use by earlier
code of its own. :class:`Job` is a job as data, for the fork server
(:mod:`rippleb.engine.forkserver`), which passes the registry it inherited; another executor
passes one.
"""

from __future__ import annotations

import dataclasses
import json
import pickle
import time
import traceback
from dataclasses import dataclass

import numpy as np

from rippleb.engine.cache import Artefact, load_log, log_bytes, pack, store
from rippleb.data import SensorLog
from rippleb import metrics, rebuilt, truthfree
from rippleb.metrics import Truth
from rippleb.registry import one_line
from rippleb.scorable import NO_REFERENCE, NO_REFERENCE_MESSAGE, implausible
from rippleb.engine.rows import FITTING, SCORED
from rippleb.streaming import InvalidOutput, prepare_blocks, stream

#: Everything the metrics compare with: the per-sample arrays and events of
#: :class:`~rippleb.metrics.Truth` (its own list) plus the two torque columns.
TRUTH_ARRAYS = metrics.TRUTH_ARRAYS + ("torque_true", "torque_ref", "torque_gear")


@dataclass(frozen=True)
class Job:
    """A job as data, so it can be sent to the process that forks it
    (:mod:`rippleb.engine.forkserver`): ``job(registry)`` runs it and returns message bytes.

    ``kind`` is ``simulate`` (``args`` of :func:`simulate_case`), ``fit`` (of
    :func:`fit_method` without the registry) or ``row`` (of :func:`run_row` without the
    registry: method, params, calibration, evaluation, fitted, fit_info).
    """

    kind: str
    args: tuple

    def __call__(self, registry) -> bytes:
        if self.kind == "simulate":
            return simulate_case(*self.args)
        if self.kind == "fit":
            return fit_method(*self.args, registry)
        method, params, calibration, evaluation, fitted, fit_info = self.args
        return row_message(run_row(method, params, calibration, evaluation, registry,
                                   fitted=fitted, fit_info=fit_info))


def visible_log(log: SensorLog, role: str) -> SensorLog:
    """What a method may see of ``log``: a calibration keeps ``torque_ref``, a scored log
    keeps neither reference; ``torque_true`` never."""
    return log.for_method(keep_ref=(role == FITTING))


def simulate_case(scenario, seed: int, condition: str, paths: dict, device_seed: int | None = None) -> bytes:
    """Simulate once; store the visible log of each role in ``paths`` (role -> path).

    ``device_seed`` (a sealed run, :mod:`rippleb.engine.sealing`) is simulated instead of
    ``seed``; the visible logs still name the public ``seed``, never the secret one.
    Returns :func:`rippleb.engine.cache.pack` bytes: the truth arrays and, in ``info``, the
    ``fs``, each role's artefact (path and hash) and ``invalid``: why the log is not a
    joint that exists (:func:`rippleb.simulator.validity.check_simulation`), or ''.
    """
    from rippleb.simulator import simulate
    from rippleb.simulator.validity import check_simulation

    sim = simulate(scenario, seed if device_seed is None else device_seed, condition=condition)
    truth = Truth.from_simulation(sim)
    log = sim.log if device_seed is None else dataclasses.replace(sim.log, meta={**sim.log.meta, "seed": seed})
    artefacts = {role: _store_log(path, visible_log(log, role)) for role, path in paths.items()}
    return truth_message(truth, artefacts, sim.log.spec.block_size, check_simulation(sim) or "")


def _store_log(path, log: SensorLog) -> dict:
    artefact = store(path, log_bytes(log))
    return {"path": artefact.path, "sha256": artefact.sha256}


def truth_message(truth: Truth, artefacts: dict, block_size: int, invalid: str = "") -> bytes:
    """The truth, the tick size, the artefacts and the validity of one case as message bytes."""
    arrays = {name: getattr(truth, name) for name in TRUTH_ARRAYS}
    return pack(arrays, {"fs": truth.fs, "block_size": int(block_size), "artefacts": artefacts,
                         "invalid": invalid})


def truth_from_message(arrays: dict, info: dict) -> Truth:
    """The :class:`Truth` sent by :func:`simulate_case`."""
    return Truth(fs=float(info["fs"]), **{name: arrays.get(name) for name in TRUTH_ARRAYS})


def fit_method(method: str, params: dict | None, calibration, registry) -> bytes:
    """Fit ``method`` on ``calibration`` and pickle it.

    Returns message bytes whose info holds ``status``, ``message``, ``params`` and
    ``fit_s`` and, if the fitted method could be pickled, whose array ``fitted`` holds the
    pickle. The runner stores it (:func:`rippleb.engine.cache.store`): a method's worker sees the
    cache read-only (:func:`rippleb.engine.isolation.confine_files`).
    """
    calibration = load_log(calibration)  # verified before any method code runs
    info = {"status": "ok", "message": "", "params": ""}
    try:
        cls = registry.get(method).load()
        fitted, info["params"], info["fit_s"] = _fit(cls, params, calibration)
    except Exception as exc:  # the fit's failure becomes the status of each of its rows
        traceback.print_exc()
        return pack({}, {**info, "status": "error", "message": one_line(exc)})
    try:
        blob = pickle.dumps(fitted, protocol=pickle.HIGHEST_PROTOCOL)
    except Exception:  # not picklable (a lambda, a handle): its rows fit it themselves
        return pack({}, info)
    return pack({"fitted": np.frombuffer(blob, dtype=np.uint8)}, info)


def _fit(cls, params, calibration: SensorLog):
    t0 = time.perf_counter()
    method = cls(**(params or {}))
    params_text = params_json(method)
    method.fit(calibration.for_method(keep_ref=True))
    return method, params_text, time.perf_counter() - t0


def run_row(method: str, params: dict | None, calibration, evaluation, registry,
            fitted: Artefact | None = None, fit_info: dict | None = None) -> dict:
    """The row job: fit (or load the fitted method), ``reset``, stream ``evaluation``.

    Returns a dict with ``info`` (status, message, params, fit_s, n_samples), and for an
    ``ok`` row the ``estimate`` [Nm] and ``ticks`` (ns per ``step`` call).
    """
    evaluation = visible_log(load_log(evaluation), SCORED)
    blob = fitted.read() if fitted is not None else None
    calibration = load_log(calibration) if fitted is None else None
    info = {"status": "ok", "message": "", "params": "", "n_samples": len(evaluation), **(fit_info or {})}
    try:
        cls = registry.get(method).load()
        if blob is not None:
            instance = pickle.loads(blob)  # the method's own pickle, verified by hash
        else:
            instance, info["params"], info["fit_s"] = _fit(cls, params, calibration)
        instance.reset(evaluation.spec)
        estimate, ticks = stream(instance.step, prepare_blocks(evaluation), len(evaluation))
    except InvalidOutput as exc:
        return {"info": {**info, "status": "invalid", "message": str(exc)}}
    except Exception as exc:  # any failure of the method is its row's status, never the run's
        traceback.print_exc()
        return {"info": {**info, "status": "error", "message": one_line(exc)}}
    return {"info": info, "estimate": estimate, "ticks": ticks}


def row_message(result: dict) -> bytes:
    """:func:`run_row`'s result as message bytes."""
    return pack({k: result[k] for k in ("estimate", "ticks") if k in result}, result["info"])


def params_json(method) -> str:
    """A method's ``get_params()`` as sorted JSON ('' if it cannot say)."""
    try:
        return json.dumps(method.get_params(), sort_keys=True, default=repr)
    except Exception:  # a broken get_params must not cost the row
        return ""


def check_estimate(arrays: dict, n_samples: int, n_ticks: int) -> tuple[np.ndarray, np.ndarray] | str:
    """The estimate and ticks a row sent, or why they cannot be scored (one line).

    The runner re-checks in its own process what the streaming loop checked in the
    row's: a row that claims ``ok`` with a wrong-length or non-finite estimate is
    ``invalid``, whatever it says.
    """
    estimate, ticks = arrays.get("estimate"), arrays.get("ticks")
    if estimate is None or ticks is None:
        return "the row sent no estimate"
    if estimate.dtype.kind != "f" or estimate.shape != (n_samples,):
        return f"estimate of shape {estimate.shape} dtype {estimate.dtype}, expected {n_samples} floats"
    if not np.isfinite(estimate).all():
        return "estimate holds NaN/inf values"
    if ticks.dtype.kind not in "iu" or ticks.shape != (n_ticks,):
        return f"tick times of shape {ticks.shape}, expected {n_ticks}"
    return estimate, ticks


def score_or_invalid(estimate: np.ndarray, truth: Truth) -> dict:
    """The accuracy columns of an estimate (:func:`rippleb.metrics.score`), its truth-free
    columns (:func:`rippleb.truthfree.truth_free_scores`) and, on a log with a model
    reference, its error against the rebuilt torque (:func:`rippleb.rebuilt.reference_scores`);
    or, when they cannot stand as an ``ok`` row, ``{"status": "invalid", "message": why}``.

    Every accuracy column must be finite or NaN (NaN: not defined for this log, e.g. no
    ``torque_true`` in a recording), and the errors against each reference the log has must
    be finite. A finite estimate can still overflow them (a strain scaled by 1e306 gave
    ``rms_error_ref_nm = inf``); the overflow itself is expected here, hence no warning.
    A recorded log's row is ``invalid`` too when its estimate is beyond the joint's range,
    and :data:`~rippleb.scorable.NO_REFERENCE` when the log has no reference (:mod:`rippleb.scorable`).
    """
    why = implausible(estimate, truth.torque_limit)
    if why:
        return {"status": "invalid", "message": why}
    with np.errstate(over="ignore", invalid="ignore"):
        scores = {**metrics.score(estimate, truth), **truthfree.truth_free_scores(estimate, truth),
                  **rebuilt.reference_scores(estimate, truth)}
    needed = {c for c, ref in (("rms_error_nm", truth.torque_true), ("max_error_nm", truth.torque_true),
                                ("rms_error_ref_nm", truth.torque_ref), ("max_error_ref_nm", truth.torque_ref))
              if ref is not None}
    bad = [f"{c} = {v}" for c, v in scores.items() if np.isinf(v) or (c in needed and not np.isfinite(v))]
    if bad:
        return {"status": "invalid", "message": f"its scores are not finite ({', '.join(bad)}): the estimate "
                                                f"or the log is beyond what float64 can score"}
    if truth.torque_true is None and truth.torque_ref is None:
        return {**scores, "status": NO_REFERENCE, "message": NO_REFERENCE_MESSAGE}
    return scores

