"""rippleb: a benchmark of torque-ripple cancellation for harmonic-drive torque sensors.

The public API is re-exported here; see the README for the CLI.
"""

from rippleb.data import JointSpec, SensorBlock, SensorLog, make_log, read_log, write_log
from rippleb.errors import InputError, PluginError, RipplebError
from rippleb.method import Method

__version__ = "0.1.0"

__all__ = [
    "InputError",
    "JointSpec",
    "Method",
    "PluginError",
    "RipplebError",
    "SensorBlock",
    "SensorLog",
    "__version__",
    "make_log",
    "read_log",
    "write_log",
]
