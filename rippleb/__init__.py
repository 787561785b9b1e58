"""rippleb: a benchmark of torque-ripple cancellation for harmonic-drive torque sensors.

The public API is re-exported here; see the README for the CLI.
"""

from __future__ import annotations

import _signal  # the C module: signal.py builds enums, milliseconds in which a Ctrl-C is a traceback
import sys as _sys

_early_signals: list[int] = []


def _is_the_program(argv: list[str]) -> bool:
    """The ``rippleb`` program itself: ``python -m rippleb`` or its console script. Read
    from the command line the process started with (``sys.orig_argv``): multiprocessing's
    spawned children (a local Dask cluster's workers) get their parent's ``sys.argv`` and
    must keep their signals."""
    if any(a == "-m" and b == "rippleb" for a, b in zip(argv, argv[1:])):
        return True
    script = next((a for a in argv[1:] if not a.startswith("-")), "")
    return script.rsplit("/", 1)[-1] == "rippleb"


if _is_the_program(list(getattr(_sys, "orig_argv", []))):
    # The `rippleb` command: from its first line, Ctrl-C and SIGTERM are recorded, and
    # raised where the command can report them in one line (rippleb.cli.entry), not as a
    # traceback from the middle of an import. Noted here with built-ins only, before any
    # module is read from disk (a Ctrl-C while rippleb.interrupts loaded was a traceback:
    # 2 of 150 random moments under 0.4 s). Importing rippleb as a library does not do this.
    for _signum in (_signal.SIGTERM, _signal.SIGINT):
        if _signum == _signal.SIGTERM or _signal.getsignal(_signum) is _signal.default_int_handler:
            _signal.signal(_signum, lambda signum, frame: _early_signals.append(signum))
    from rippleb import interrupts as _interrupts

    _interrupts.hold_from_start(_early_signals)
else:
    from rippleb import interrupts as _interrupts  # noqa: F401 - rippleb.interrupts, as a program has it

from rippleb import numerics  # noqa: E402

# Before anything loads numpy (rippleb.interrupts does not): the same floating-point paths
# on every x86-64 CPU with AVX2, so a published row re-runs to the last bit
# (rippleb/numerics.py, docs/reproducibility.md).
numerics.pin()

from typing import TYPE_CHECKING  # noqa: E402

from rippleb._lazy import lazy_exports  # noqa: E402

#: Where each public name lives. They are imported on first use (PEP 562), so that
#: ``import rippleb`` and ``python -m rippleb --help`` do not pay for numba, scipy and
#: pinocchio until a name that needs them is asked for.
_EXPORTS = {
    "CONDITIONS": "rippleb.simulator.conditions",
    "DEFAULT_CONDITION": "rippleb.simulator.conditions",
    "DaskExecutor": "rippleb.engine.dask.executor",
    "JointSpec": "rippleb.data",
    "SensorBlock": "rippleb.data",
    "SensorLog": "rippleb.data",
    "make_log": "rippleb.data",
    "read_log": "rippleb.log_files",
    "write_log": "rippleb.log_files",
    "InputError": "rippleb.errors",
    "PluginError": "rippleb.errors",
    "RipplebError": "rippleb.errors",
    "Method": "rippleb.method",
    "run": "rippleb.engine.runner",
    "run_log": "rippleb.engine.runner",
    "Scenario": "rippleb.simulator.scenario",
    "builtin_scenarios": "rippleb.simulator.scenario",
    "load_scenario": "rippleb.simulator.scenario",
    "scored_scenarios": "rippleb.simulator.scenario",
    "Simulation": "rippleb.simulator",
    "simulate": "rippleb.simulator",
    "run_sweep": "rippleb.engine.sweep",
}

if TYPE_CHECKING:  # what static tools see: the same names, imported eagerly
    from rippleb.simulator.conditions import CONDITIONS, DEFAULT_CONDITION
    from rippleb.engine.dask.executor import DaskExecutor
    from rippleb.data import JointSpec, SensorBlock, SensorLog, make_log
    from rippleb.log_files import read_log, write_log
    from rippleb.errors import InputError, PluginError, RipplebError
    from rippleb.method import Method
    from rippleb.engine.runner import run, run_log
    from rippleb.simulator.scenario import Scenario, builtin_scenarios, load_scenario, scored_scenarios
    from rippleb.simulator import Simulation, simulate
    from rippleb.engine.sweep import run_sweep


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)


from rippleb.version import __version__  # noqa: E402 - what setuptools-scm recorded at build time

__all__ = [
    "CONDITIONS",
    "DEFAULT_CONDITION",
    "DaskExecutor",
    "InputError",
    "JointSpec",
    "Method",
    "PluginError",
    "RipplebError",
    "SensorBlock",
    "Scenario",
    "SensorLog",
    "Simulation",
    "__version__",
    "builtin_scenarios",
    "load_scenario",
    "make_log",
    "read_log",
    "run",
    "run_log",
    "run_sweep",
    "scored_scenarios",
    "simulate",
    "write_log",
]
