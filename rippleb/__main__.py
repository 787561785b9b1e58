"""``python -m rippleb``: the same as the ``rippleb`` command."""

from rippleb.cli import entry

entry()
