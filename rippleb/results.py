"""Result rows: column order, system information, and the atomically replaced CSV.

One row per method x scenario x seed, in benchopt's long format: the accuracy and
timing columns, then provenance (method parameters, calibration source, rippleb,
Python, platform and CPU) so that a row read alone says where it came from.
"""

from __future__ import annotations

import functools
import os
import platform
from pathlib import Path

from rippleb.errors import InputError
from rippleb.files import atomic_path
from rippleb.metrics import METRIC_COLUMNS

KEY_COLUMNS = ("method", "scenario", "seed")
COLUMNS = (KEY_COLUMNS + ("status",) + METRIC_COLUMNS
           + ("message", "n_samples", "fit_s", "wall_s", "calibration", "params",
              "rippleb_version", "python", "numpy", "platform", "cpu", "run_id"))
STATUSES = ("ok", "error", "invalid", "timeout")


@functools.lru_cache(maxsize=1)
def system_info() -> dict[str, str]:
    """Versions and machine, the same for every row of one run."""
    import numpy

    from rippleb import __version__

    return {"rippleb_version": __version__, "python": platform.python_version(),
            "numpy": numpy.__version__, "platform": platform.platform(terse=True), "cpu": _cpu_name()}


def _cpu_name() -> str:
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.lower().startswith("model name"):
                    return f"{line.split(':', 1)[1].strip()} x{os.cpu_count()}"
    except OSError:
        pass
    return f"{platform.processor() or platform.machine()} x{os.cpu_count()}"


class ResultsFile:
    """``DIR/results.csv``, rewritten atomically after each finished row.

    Writing a temporary file and ``os.replace``-ing it means a reader, a SIGINT or a
    ``kill -9`` only ever sees a complete CSV of finished rows. The cost (tens of rows,
    milliseconds) is negligible next to one row.

    Parameters
    ----------
    path
        The CSV file, or None to keep rows in memory only.
    resume
        Keep the rows already in ``path``.
    """

    def __init__(self, path: Path | None, resume: bool = False):
        self.path = path
        self.rows: list[dict] = []
        if path is not None and resume and path.is_file():
            self.rows = read_rows(path)

    def done_keys(self) -> set[tuple]:
        """``(method, scenario, seed)`` of every row already finished."""
        return {(r["method"], r["scenario"], int(r["seed"])) for r in self.rows}

    def add(self, row: dict) -> None:
        """Append one row and replace the file."""
        self.rows.append(row)
        if self.path is not None:
            self._write()

    def frame(self):
        """The rows as a DataFrame with the standard columns first."""
        import pandas as pd

        frame = pd.DataFrame(self.rows)
        extra = sorted(c for c in frame.columns if c not in COLUMNS)
        return frame.reindex(columns=list(COLUMNS) + extra)

    def _write(self) -> None:
        with atomic_path(self.path) as tmp:
            self.frame().to_csv(tmp, index=False)


def read_rows(path: Path) -> list[dict]:
    """The rows of a results CSV as dicts (for ``--resume`` and ``report``)."""
    import pandas as pd

    try:
        frame = pd.read_csv(path, keep_default_na=True)
    except Exception as exc:  # pandas raises many types for unreadable files
        raise InputError(f"{path}: cannot read results: {str(exc).splitlines()[0]}") from None
    missing = [c for c in KEY_COLUMNS + ("status",) if c not in frame.columns]
    if missing:
        raise InputError(f"{path}: not a rippleb results file (missing column(s) {', '.join(missing)})")
    return frame.to_dict("records")

