"""Errors that reach the user as one clear line."""


class RipplebError(Exception):
    """Base class of rippleb's own errors; the CLI prints them as one line and exits 2."""


class InputError(RipplebError, ValueError):
    """Bad input from a user: a scenario file, a log, a name or a path.

    The message names the file, key, column or plugin at fault.
    """


class PluginError(RipplebError):
    """A method plugin that cannot be loaded or that clashes with another."""


class EnvironmentLost(RipplebError):
    """What a run needs went away mid-run (a Dask scheduler): one line, exit 2, and the
    run can be finished with ``--resume`` (the CLI adds what was kept and the command)."""

    resumable = True


class RunWarning(UserWarning):
    """Something a run or a reader repaired or will do again, said in one line."""
