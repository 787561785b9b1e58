"""``rippleb check``'s work: each conformance check in the sandboxed worker of a method.

The checks are :mod:`rippleb.engine.conformance`'s. ``rippleb check NAME`` runs each as a
job of its own (:class:`CheckJob`) in the same worker a run's rows get
(:mod:`rippleb.engine.process`): its walls, a time limit and a memory limit, its output to
nowhere. So a check that hangs is cut at the limit, one that ends its process or raises
fails with the check named, and the checks after it still run; no plugin code runs in the
``rippleb`` process. The first check fits the method and computes the estimate the others
compare with; they get its fitted state (pickled in its worker) and that estimate, as a
row gets its fit. The logs are simulated by rippleb once the fork server has started, so no
job's memory holds their truth; each job gets them as a method may see them.
"""

from __future__ import annotations

import functools
import pickle
from dataclasses import dataclass

import numpy as np

from rippleb.data import SensorLog
from rippleb.engine.cache import pack, unpack
from rippleb.engine.conformance import checks, default_logs, subject
from rippleb.registry import one_line


def failure(exc: BaseException) -> str:
    """A failed check in one line: an assertion's own message, or ``Type: first line`` of
    any other error."""
    if isinstance(exc, AssertionError) and str(exc).strip():
        return " ".join(str(exc).split())
    return one_line(exc)


def in_process(checked, listed):
    """``attempt(number) -> '' or why it failed`` running check ``number`` of ``listed`` on the
    :class:`~rippleb.engine.conformance.Subject` ``checked`` in this process (tests)."""
    def attempt(number: int) -> str:
        try:
            listed[number][1](checked)
        except Exception as exc:  # noqa: BLE001 - a method may raise anything; it is one line
            return failure(exc)
        return ""
    return attempt


@dataclass(frozen=True)
class CheckJob:
    """Check ``number`` of :func:`~rippleb.engine.conformance.checks` on ``method(**params)``,
    as a job of a method's worker: its logs as a method may see them travel with it; the
    fitted state and estimate of the first check (``fitted``, ``base``) with the later ones.
    Returns :func:`~rippleb.engine.cache.pack` bytes: ``failed`` ('' when it passed) and, from
    the first check, the estimate and the fitted state's pickle."""

    method: str
    params: dict
    calibration: SensorLog
    log: SensorLog
    number: int
    fitted: bytes | None = None
    base: np.ndarray | None = None

    def __call__(self, registry) -> bytes:
        return self.prepare(registry)()

    def prepare(self, registry):
        """Nothing to read: the logs travel with the job."""
        return functools.partial(self.run, registry)

    def run(self, registry) -> bytes:
        checked = subject(registry.get(self.method).load(), self.params, log=self.log, calibration=self.calibration)
        listed = checks()
        if self.number and self.fitted is not None:
            checked.fitted, checked.base = pickle.loads(self.fitted), self.base
        elif self.number:   # a fitted method that cannot be pickled: fitted again here
            listed[0][1](checked)
        why = in_process(checked, listed)(self.number)
        if self.number or why:
            return pack({}, {"failed": why})
        try:
            blob = np.frombuffer(pickle.dumps(checked.fitted, protocol=pickle.HIGHEST_PROTOCOL), dtype=np.uint8)
        except Exception:  # noqa: BLE001 - not picklable: each later check fits again
            blob = None
        return pack({"base": checked.base, "fitted": blob}, {"failed": ""})


class SandboxedChecks:
    """``attempt(number) -> '' or why it failed``, each check a sandboxed job (module
    docstring); use in a ``with`` block, which starts and ends the fork server.

    Parameters
    ----------
    registry
        The methods this process can load.
    name, params
        The method and its constructor parameters.
    timeout, memory_mb
        Each check's limits (None: none).
    """

    def __init__(self, registry, name: str, params: dict, timeout: float | None, memory_mb: float | None):
        self.registry = registry
        self.name = name
        self.params = params
        self.timeout = timeout
        self.memory_mb = memory_mb

    def __enter__(self) -> "SandboxedChecks":
        from rippleb.engine.process.forkserver import ForkServer
        from rippleb.engine.process.isolation import Confinement
        from rippleb.engine.process.landlock import own_package
        from rippleb.engine.process.pool import Pool

        self.server = ForkServer.start(self.registry, preload=functools.partial(_warm, self.registry, self.name))
        calibration, log = default_logs()   # after the fork: the server never holds their truth
        self.logs = calibration.for_method(keep_ref=True), log.for_method(keep_ref=False)
        self.pool = Pool(1, self.memory_mb, server=self.server)
        self.confine = Confinement(readable=own_package(self.registry, self.name))
        self.fitted = self.base = None
        return self

    def __exit__(self, *exc) -> None:
        self.pool.kill_all()
        self.server.close()

    def __call__(self, number: int) -> str:
        job = CheckJob(self.name, self.params, *self.logs, number, self.fitted, self.base)
        self.pool.submit(number, job, self.timeout, confine=self.confine)
        (fin,) = self.pool.wait()
        if fin.kind == "timeout":
            return f"no answer within {self.timeout:g} s (--timeout): the check was ended"
        if fin.kind == "raised":
            return fin.value
        if fin.kind != "done":
            return _ended(fin)
        try:
            arrays, info = unpack(fin.value)
        except Exception as exc:  # noqa: BLE001 - a method's process sent it: untrusted bytes
            return f"the check's process sent an unreadable result ({type(exc).__name__})"
        if number == 0 and not info.get("failed"):
            self.base = arrays.get("base")
            self.fitted = arrays["fitted"].tobytes() if "fitted" in arrays else None
        return str(info.get("failed", "the check's process sent no verdict"))[:2000]


def _ended(fin) -> str:
    """Why a check's process ended without a verdict, in words."""
    if fin.kind == "died":
        code = fin.value
        return (f"its process was killed by signal {-code}" if code is not None and code < 0
                else f"its process ended with exit code {code} before it reported")
    if fin.kind == "oversized":
        return f"its process sent {fin.value} bytes, more than a check's result can hold"
    return f"its process wrote into rippleb's control pipe ({fin.kind}); the check was ended"


def _warm(registry, name: str) -> None:
    """In the fork server: the simulator and, if ``name`` is built in, its method (rippleb's
    code only; a plugin is imported only by the checks' workers)."""
    from rippleb.simulator import simulation  # noqa: F401 - its compiled kernels

    if registry.get(name).origin == "builtin":
        registry.load_builtins({name})
