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
(:mod:`rippleb.engine.process.forkserver`), which passes the registry it inherited; another executor
passes one.
"""

from __future__ import annotations

import dataclasses
import pickle
import traceback
from dataclasses import dataclass

import numpy as np

from rippleb.engine.cache import Artefact, load_log, log_bytes, pack, pack_raw, store
from rippleb.data import SensorLog
from rippleb.scoring import metrics
from rippleb.scoring.metrics import Truth
from rippleb.registry import one_line
from rippleb.engine.rows import FITTING, SCORED
from rippleb import harness
from rippleb.harness import InvalidOutput

#: Everything the metrics compare with: the per-sample arrays and events of
#: :class:`~rippleb.scoring.metrics.Truth` (its own list) plus the two torque columns.
TRUTH_ARRAYS = metrics.TRUTH_ARRAYS + ("torque_true", "torque_ref", "torque_gear")


@dataclass(frozen=True)
class Job:
    """A job as data, so it can be sent to the process that forks it
    (:mod:`rippleb.engine.process.forkserver`): ``job(registry)`` runs it and returns message bytes.

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
    cache read-only (:func:`rippleb.engine.process.isolation.confine_files`).
    """
    calibration = load_log(calibration)  # verified before any method code runs
    info = {"status": "ok", "message": "", "params": ""}
    try:
        cls = registry.get(method).load()
        fitted, info["params"], info["fit_s"] = harness.fitted(cls, params, calibration)
    except Exception as exc:  # the fit's failure becomes the status of each of its rows
        traceback.print_exc()
        return pack({}, {**info, "status": "error", "message": one_line(exc)})
    try:
        blob = pickle.dumps(fitted, protocol=pickle.HIGHEST_PROTOCOL)
    except Exception:  # not picklable (a lambda, a handle): its rows fit it themselves
        return pack({}, info)
    return pack({"fitted": np.frombuffer(blob, dtype=np.uint8)}, info)


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
            instance, info["params"], info["fit_s"] = harness.fitted(cls, params, calibration)
        estimate, ticks = harness.run(instance, evaluation)
    except InvalidOutput as exc:
        return {"info": {**info, "status": "invalid", "message": str(exc)}}
    except Exception as exc:  # any failure of the method is its row's status, never the run's
        traceback.print_exc()
        return {"info": {**info, "status": "error", "message": one_line(exc)}}
    return {"info": info, "estimate": estimate, "ticks": ticks}


def row_message(result: dict) -> bytes:
    """:func:`run_row`'s result as message bytes: the estimate's float64 as they are (:func:`pack_raw`)."""
    return pack_raw({k: result[k] for k in ("estimate", "ticks") if k in result}, result["info"])

