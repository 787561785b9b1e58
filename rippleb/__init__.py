"""rippleb: a benchmark of torque-ripple cancellation for harmonic-drive torque sensors.

The public API is re-exported here; see the README for the CLI.
"""

from __future__ import annotations

from rippleb import interrupts as _interrupts

if _interrupts.is_the_program():
    # The `rippleb` command: from its first line, Ctrl-C and SIGTERM are recorded, and
    # raised where the command can report them in one line (rippleb.cli.entry), not as a
    # traceback from the middle of an import. Importing rippleb as a library does not do this.
    _interrupts.hold_from_start()

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
    "DaskExecutor": "rippleb.engine.dask_executor",
    "JointSpec": "rippleb.data",
    "SensorBlock": "rippleb.data",
    "SensorLog": "rippleb.data",
    "make_log": "rippleb.data",
    "read_log": "rippleb.data",
    "write_log": "rippleb.data",
    "InputError": "rippleb.errors",
    "PluginError": "rippleb.errors",
    "RipplebError": "rippleb.errors",
    "Method": "rippleb.method",
    "run": "rippleb.engine.runner",
    "run_log": "rippleb.engine.runner",
    "Scenario": "rippleb.scenario",
    "builtin_scenarios": "rippleb.scenario",
    "load_scenario": "rippleb.scenario",
    "scored_scenarios": "rippleb.scenario",
    "Simulation": "rippleb.simulator",
    "simulate": "rippleb.simulator",
    "run_sweep": "rippleb.engine.sweep",
}

if TYPE_CHECKING:  # what static tools see: the same names, imported eagerly
    from rippleb.simulator.conditions import CONDITIONS, DEFAULT_CONDITION
    from rippleb.engine.dask_executor import DaskExecutor
    from rippleb.data import JointSpec, SensorBlock, SensorLog, make_log, read_log, write_log
    from rippleb.errors import InputError, PluginError, RipplebError
    from rippleb.method import Method
    from rippleb.engine.runner import run, run_log
    from rippleb.scenario import Scenario, builtin_scenarios, load_scenario, scored_scenarios
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
