"""The ``rippleb`` command, one module per subcommand.

``rippleb.cli:entry`` is the console script and ``python -m rippleb`` runs it too;
:func:`main` runs one command line in this process (the tests call it).
"""

from rippleb.cli.program import entry, main

__all__ = ["entry", "main"]
