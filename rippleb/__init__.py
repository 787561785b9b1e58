"""rippleb: a benchmark of torque-ripple cancellation for harmonic-drive torque sensors.

The public API is re-exported here; see the README for the CLI.
"""

from rippleb.simulator.conditions import CONDITIONS, DEFAULT_CONDITION
from rippleb.dask_executor import DaskExecutor
from rippleb.data import JointSpec, SensorBlock, SensorLog, make_log, read_log, write_log
from rippleb.errors import InputError, PluginError, RipplebError
from rippleb.method import Method
from rippleb.runner import run, run_log
from rippleb.scenario import Scenario, builtin_scenarios, load_scenario, scored_scenarios
from rippleb.simulator import Simulation, simulate
from rippleb.sweep import run_sweep


def _installed_version() -> str:
    """The version setuptools-scm recorded at build time (``rippleb/_version.py``, not in
    git), else the installed distribution's, else ``unknown``."""
    try:
        from rippleb._version import __version__ as built
    except ImportError:
        from importlib import metadata

        try:
            return metadata.version("rippleb")
        except metadata.PackageNotFoundError:
            return "unknown"
    return built


__version__ = _installed_version()

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
