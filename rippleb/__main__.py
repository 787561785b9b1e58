"""``python -m rippleb``: the same as the ``rippleb`` command."""

import sys

from rippleb.cli import main

sys.exit(main())
