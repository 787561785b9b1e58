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
import functools
import pickle
import traceback
from dataclasses import dataclass

from rippleb.engine.cache import Artefact, load_log, log_bytes, pack, pack_raw, store, unpack
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

    A method's worker runs it in two parts (:meth:`prepare`), so that its inputs are read
    before the walls close every file but the method's own package and the libraries.
    """

    kind: str
    args: tuple

    def __call__(self, registry) -> bytes:
        return self.prepare(registry)()

    def prepare(self, registry):
        """rippleb's part, run before the walls: read and verify the job's inputs (the cache
        is unreadable behind them); returns the part that runs the method's code."""
        if self.kind == "simulate":
            return functools.partial(simulate_case, *self.args)
        if self.kind == "fit":
            method, params, calibration = self.args
            return functools.partial(fit_method, method, params, load_log(calibration), registry)
        method, params, calibration, evaluation, fitted, fit_info = self.args
        evaluation = visible_log(load_log(evaluation), SCORED)
        blob = fitted.read() if isinstance(fitted, Artefact) else fitted
        calibration = load_log(calibration) if blob is None else None
        return lambda: row_message(run_row(method, params, calibration, evaluation, registry,
                                           fitted=blob, fit_info=fit_info))


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


def fit_method(method: str, params: dict | None, calibration, registry) -> tuple[bytes, bytes, bytes]:
    """Fit ``method`` on ``calibration`` and pickle it.

    Returns the message as three pieces (:func:`fit_message`): the pickle (empty if the
    fit failed, or if the fitted method cannot be pickled: its rows then fit it
    themselves), the info (``status``, ``message``, ``params``, and the in-process
    ``fit_s`` the runner replaces with the time measured outside), and the info's length.
    The runner receives it into a file of the cache (:func:`read_fit`): a method's worker
    cannot write there (:func:`rippleb.engine.process.isolation.confine_files`).
    """
    calibration = load_log(calibration)  # verified before any method code runs
    info = {"status": "ok", "message": "", "params": ""}
    try:
        cls = registry.get(method).load()
        fitted, info["params"], info["fit_s"] = harness.fitted(cls, params, calibration)
    except Exception as exc:  # the fit's failure becomes the status of each of its rows
        traceback.print_exc()
        return fit_message(b"", {**info, "status": "error", "message": one_line(exc)})
    try:
        blob = pickle.dumps(fitted, protocol=pickle.HIGHEST_PROTOCOL)
    except Exception:  # not picklable (a lambda, a handle): its rows fit it themselves
        blob = b""
    return fit_message(blob, info)


def fit_message(blob: bytes, info: dict) -> tuple[bytes, bytes, bytes]:
    """A fit's result: the pickle first, then its info (:func:`rippleb.engine.cache.pack`
    bytes), then their length in 8 bytes, so the info is read from the end of the file the
    pickle stays in."""
    meta = pack({}, info)
    return blob, meta, len(meta).to_bytes(8, "little")


def read_fit(path) -> tuple[dict, int]:
    """The info of the fit result in the file ``path`` and the length of its pickle; the
    file is cut to the pickle. Raises ``ValueError`` when it is not what :func:`fit_message`
    makes (the bytes of a method's process are untrusted)."""
    with open(path, "r+b") as fh:
        size = fh.seek(0, 2)
        if size < 8:
            raise ValueError("a fit result shorter than its trailer")
        fh.seek(size - 8)
        length = int.from_bytes(fh.read(8), "little")
        if length > min(size - 8, 2**20):
            raise ValueError("a fit result whose info does not fit it")
        fh.seek(size - 8 - length)
        _, info = unpack(fh.read(length))
        fh.truncate(size - 8 - length)
    return info, size - 8 - length


def run_row(method: str, params: dict | None, calibration, evaluation, registry,
            fitted: Artefact | bytes | None = None, fit_info: dict | None = None) -> dict:
    """The row job: fit (or load the fitted method: its pickle, or the artefact holding it),
    ``reset``, stream ``evaluation``.

    Returns a dict with ``info`` (status, message, params, fit_s, n_samples), and for an
    ``ok`` row the ``estimate`` [Nm] and ``ticks`` (ns per ``step`` call).
    """
    evaluation = visible_log(load_log(evaluation), SCORED)
    blob = fitted.read() if isinstance(fitted, Artefact) else fitted
    calibration = load_log(calibration) if blob is None else None
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

