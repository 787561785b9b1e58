"""Result rows: column order, system information, the atomically replaced CSV, and its checked reader.

One row per method x scenario x condition x seed, in benchopt's long format: the
accuracy and timing columns, then provenance (method parameters, calibration source,
the scenario's content hash, rippleb, Python, platform and CPU) so that a row read
alone says what it ran and where.

:func:`read_rows` (used by ``--resume`` and ``rippleb report``) trusts nothing it reads:
it checks every row column by column and drops, with one warning line, rows that are
truncated, hold text in a numeric cell, have an unknown status, or repeat a key.
"""

from __future__ import annotations

import bisect
import csv
import functools
import io
import math
import os
import platform
import time
import warnings
from pathlib import Path

import numpy as np

from rippleb.simulator.conditions import DEFAULT_CONDITION
from rippleb import integrity
from rippleb.errors import InputError, RunWarning  # noqa: F401 - RunWarning: re-exported
from rippleb.files import atomic_path, open_appending
from rippleb.scoring.metrics import LATER_COLUMNS, METRIC_COLUMNS
from rippleb.printable import csv_read, csv_text, escaped
from rippleb.scoring.scorable import MEASURED, NO_REFERENCE  # noqa: F401 - MEASURED re-exported
from rippleb.scoring.rebuilt import REFERENCE_COLUMNS
from rippleb.scoring.truthfree import TRUTH_FREE_COLUMNS

KEY_COLUMNS = ("method", "scenario", "condition", "seed")
# The truth-free and reference columns came later: a results file without them still reads (as n/a).
COLUMNS = (KEY_COLUMNS + ("status",) + METRIC_COLUMNS + TRUTH_FREE_COLUMNS + REFERENCE_COLUMNS
           + ("message", "n_samples", "fit_s", "wall_s", "calibration", "params", "scenario_sha256",
              "rippleb_version", "python", "numpy", "platform", "cpu", "numerics", "run_id"))
NUMERIC_COLUMNS = METRIC_COLUMNS + TRUTH_FREE_COLUMNS + REFERENCE_COLUMNS + ("n_samples", "fit_s", "wall_s")
STATUSES = ("ok", "error", "invalid", "timeout", NO_REFERENCE)
#: An ``ok`` row holds at least one of these: an error against a reference, or, on a log
#: with none, a truth-free score.
SCORE_COLUMNS = ("rms_error_nm", "rms_error_ref_nm") + TRUTH_FREE_COLUMNS
#: message prefix of rows that failed for a reason outside the method (``--resume`` retries them)
ENVIRONMENT = "environment: "
#: The whole of ``results.csv`` is rewritten from memory at most this often [s] ...
REWRITE_INTERVAL_S = 2.0
#: ... and at most once per this many times the last rewrite took (<= 5 % of the time).
REWRITE_SHARE = 20.0


@functools.lru_cache(maxsize=1)
def system_info() -> dict[str, str]:
    """Versions and machine, the same for every row of one run."""
    import numpy

    from rippleb import numerics
    from rippleb.version import __version__

    return {"rippleb_version": __version__, "python": platform.python_version(),
            "numpy": numpy.__version__, "platform": platform.platform(terse=True), "cpu": _cpu_name(),
            "numerics": numerics.state()}


def _cpu_name() -> str:
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.lower().startswith("model name"):
                    return f"{line.split(':', 1)[1].strip()} x{os.cpu_count()}"
    except OSError:
        pass
    return f"{platform.processor() or platform.machine()} x{os.cpu_count()}"


def row_key(row: dict) -> tuple:
    """``(method, scenario, condition, seed)`` of a row dict, followed by ``(name, value)``
    of each swept parameter (:data:`rippleb.engine.params.PARAMS`) the row has a column for."""
    base = (row["method"], row["scenario"], row.get("condition", DEFAULT_CONDITION), int(row["seed"]))
    return base + tuple((name, float(row[name])) for name in swept_columns(row))


def _swept_kind(name: str) -> type:
    from rippleb.engine.params import PARAMS

    return PARAMS[name].kind


def swept_columns(columns) -> list[str]:
    """The swept-parameter columns among ``columns`` (a row dict or a header), sorted."""
    from rippleb.engine.params import PARAMS

    return sorted(name for name in columns if name in PARAMS)


class ResultsFile:
    """``DIR/results.csv``: each finished row appended at once, the whole file replaced
    atomically from memory every :data:`REWRITE_INTERVAL_S` at most and by :meth:`flush`.

    A finished row is on disk as soon as :meth:`add` returns: its CSV line is appended with
    one write (a reader skips a last line the writer did not finish, :func:`read_rows`).
    The rows in memory are the authority: :meth:`flush` (at the end of a run, on an
    interrupt, when a row brings a new column) and the periodic rewrite replace the file,
    through a temporary file and ``os.replace``, with every row in key order, so a reader,
    a SIGINT or a ``kill -9`` never sees half a file and an edit of the file by anyone
    else lasts until the next rewrite. Rewriting after every row cost time quadratic in
    the rows (36 s of a 6400-row run; an hour for 64 000); appending is constant per row,
    and the periodic rewrite, at most every few seconds and at most a twentieth of the
    time, stays linear. Each row is formatted into its CSV line once, when it is added.

    Parameters
    ----------
    path
        The CSV file, or None to keep rows in memory only.
    resume
        Keep the (checked) rows already in ``path``.
    """

    def __init__(self, path: Path | None, resume: bool = False):
        self.path = path
        # the MACs of the rows (rippleb.integrity), from the run directory's run.json
        self.ledger = integrity.Ledger(path.parent) if path is not None else None
        self.rows: list[dict] = []
        self._header: list[str] = list(COLUMNS)
        self._lines: list[tuple[tuple, str]] = []   # (row key, CSV line), in key order
        self._written_at = -math.inf                   # monotonic time of the last rewrite
        self._rewrite_s = 0.0                          # how long it took
        if path is not None and resume and path.is_file():
            self.rows = integrity.verified_rows(path.parent, read_rows(path), path)
            self._format_all()
            self.ledger.rewrite(self.rows)

    def done_keys(self) -> set[tuple]:
        """``(method, scenario, condition, seed)`` of every row already finished."""
        return {row_key(r) for r in self.rows}

    def drop_environmental(self) -> list[dict]:
        """Remove and return the rows that failed for an environmental reason."""
        dropped = [r for r in self.rows if r.get("status") != "ok"
                   and str(r.get("message", "")).startswith(ENVIRONMENT)]
        self.rows = [r for r in self.rows if r not in dropped]
        self._format_all()
        return dropped

    def add(self, row: dict) -> None:
        """Keep one finished row and put it on disk: appended, or with the whole file
        rewritten (the first row, a new column, or the rewrite interval passed). A
        message is kept with its control characters escaped (:mod:`rippleb.printable`):
        a method's text never reaches a terminal or a README able to act."""
        if row.get("message") is not None:
            row = {**row, "message": escaped(row["message"])}
        self.rows.append(row)
        if any(name not in self._header for name in row):
            self._format_all()   # a new column: every line gets a cell for it
            if self.ledger is not None:
                self.ledger.append(row)
            self.flush()
            return
        line = self._line(row)
        bisect.insort(self._lines, (row_key(row), line), key=lambda item: item[0])
        if self.ledger is not None:
            self.ledger.append(row)   # its MAC first: a row on disk always has one
        due = max(REWRITE_INTERVAL_S, REWRITE_SHARE * self._rewrite_s)
        if self.path is None or time.monotonic() - self._written_at >= due or not self.path.is_file():
            self.flush()
        else:
            with open_appending(self.path) as fh:
                fh.write(line)

    def flush(self) -> None:
        """Replace the file with the rows in memory, in key order."""
        if self.path is not None:
            start = time.monotonic()
            text = self._line(dict(zip(self._header, self._header))) + "".join(
                line for _, line in self._lines)
            with atomic_path(self.path) as tmp:
                tmp.write_text(text, encoding="utf-8")
            self._written_at = time.monotonic()
            self._rewrite_s = self._written_at - start

    def frame(self):
        """The rows as a DataFrame, standard columns first, sorted by the row key."""
        import pandas as pd

        frame = pd.DataFrame(self.rows)
        extra = sorted(c for c in frame.columns if c not in COLUMNS)
        frame = frame.reindex(columns=list(COLUMNS) + extra)
        if len(frame):
            keys = list(KEY_COLUMNS) + swept_columns(frame.columns)
            frame = frame.sort_values(keys, kind="stable").reset_index(drop=True)
        return frame

    def _format_all(self) -> None:
        extra = sorted({name for row in self.rows for name in row} - set(COLUMNS))
        self._header = list(COLUMNS) + extra
        self._lines = sorted(((row_key(row), self._line(row)) for row in self.rows),
                             key=lambda item: item[0])

    def _line(self, row: dict) -> str:
        return _csv_line(self._header, [_cell(row.get(name)) for name in self._header])


_cell = integrity.cell_text


def is_text_column(name: str) -> bool:
    """Whether a column of a results file holds text (a name, a status, a message), not a
    number: its cells are written through :func:`rippleb.printable.csv_text`, so that a
    spreadsheet runs none of them as a formula (docs/robustness.md, section 11)."""
    return name not in NUMERIC_COLUMNS and name != "seed" and name not in swept_columns([name])


def _csv_line(header: list[str], cells: list[str]) -> str:
    """One line of a results file: ``cells`` (as :func:`_cell` or a reader gave them) under
    ``header``, every text cell neutralised for spreadsheets, numbers as they are."""
    buffer = io.StringIO()
    csv.writer(buffer, lineterminator="\n").writerow(
        [csv_text(cell) if cell and is_text_column(name) else cell for name, cell in zip(header, cells)])
    return buffer.getvalue()


def say_other_versions(rows: list[dict], out_dir) -> None:
    """One warning line when a resumed run's finished rows were made by another rippleb
    version than the rows this process is about to add (both are kept; their numbers may
    differ where the code changed)."""
    from rippleb.version import __version__

    counts: dict[str, int] = {}
    for row in rows:
        version = str(row.get("rippleb_version") or "not recorded")
        if version != __version__:
            counts[version] = counts.get(version, 0) + 1
    if counts:
        seen = ", ".join(f"{n} by {v}" for v, n in sorted(counts.items()))
        warnings.warn(f"{out_dir}/results.csv: {sum(counts.values())} finished row(s) were made by "
                      f"another rippleb version ({seen}); this is {__version__}, and its new rows are "
                      f"added beside them", RunWarning, stacklevel=3)


def read_rows(path: Path) -> list[dict]:
    """The checked rows of a results CSV (for ``--resume`` and ``report``).

    Rows that cannot be trusted are dropped with one :class:`RunWarning` line naming the
    first of them; a file without the key, status and metric columns raises
    :class:`InputError`. Every cell is read as text first (a scenario named ``NA`` stays
    ``NA``), then converted by column: ``seed`` to int, the metrics to float.
    """
    path = Path(path)
    try:
        text = _read_text(path)
        # rippleb ends every line it writes; a last line without its end is an append cut short
        unfinished = "\n" in text and not text.endswith("\n")
        if unfinished:
            text = text[: text.rindex("\n") + 1]
        lines = list(csv.reader(io.StringIO(text, newline="")))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise InputError(f"{path}: cannot read results: {getattr(exc, 'strerror', None) or exc}") from None
    if not lines:
        raise InputError(f"{path}: empty file, not a rippleb results file")
    header, body = lines[0], lines[1:]
    required = ("method", "scenario", "seed", "status") + tuple(c for c in METRIC_COLUMNS
                                                                if c not in LATER_COLUMNS)
    missing = [c for c in required if c not in header]
    if missing:
        raise InputError(f"{path}: not a rippleb results file (missing column(s) {', '.join(missing)})")
    rows, seen = [], set()
    dropped = [f"line {len(lines) + 1} is unfinished (no line end)"] if unfinished else []
    for number, cells in enumerate(body, start=2):
        if not cells:
            continue
        row, problem = _check_row(header, cells)
        if problem is None and row_key(row) in seen:
            problem = "repeats the key of an earlier row"
        if problem is not None:
            dropped.append(f"line {number} {problem}")
            continue
        seen.add(row_key(row))
        rows.append(row)
    if dropped:
        warnings.warn(f"{path}: ignored {len(dropped)} row(s) that cannot be trusted (first: {dropped[0]})",
                      RunWarning, stacklevel=2)
    return rows


def _read_text(path: Path) -> str:
    """A run directory's results file, bounded and never through a link (:mod:`rippleb.reading`)."""
    from rippleb.reading import RESULTS_BYTES, read_text

    return read_text(path, RESULTS_BYTES, "results file", in_run_dir=True)


def copy_rows(source: Path, target: Path, keys: set) -> None:
    """Copy ``source`` to ``target``, keeping the header and only the lines whose row key is
    in ``keys`` (the rows a reader verified). Each number keeps the exact text it has (a
    re-printed float could change its last digit); each text cell is written as
    :class:`ResultsFile` writes it, so a file from an older rippleb, or edited by hand,
    loses its formulas too. A line rippleb wrote is copied byte for byte."""
    text = _read_text(Path(source))
    lines = [line + "\n" for line in text.split("\n")[:-1]]   # rippleb ends every line with "\n"
    header = next(csv.reader([lines[0]]))
    kept = [_csv_line(header, header)]
    for line in lines[1:]:
        cells = next(csv.reader([line]), [])
        row, problem = _check_row(header, cells) if cells else ({}, "empty")
        if problem is None and row_key(row) in keys:
            kept.append(_csv_line(header, [csv_read(c) if is_text_column(n) else c for n, c in zip(header, cells)]))
    Path(target).write_text("".join(kept), encoding="utf-8")


def _check_row(header: list[str], cells: list[str]) -> tuple[dict, str | None]:
    if len(cells) != len(header):
        return {}, f"has {len(cells)} of {len(header)} fields (truncated?)"
    row: dict = {name: csv_read(cell) if is_text_column(name) else cell for name, cell in zip(header, cells)}
    row.setdefault("condition", DEFAULT_CONDITION)
    for name in ("method", "scenario", "condition"):
        if not row[name]:
            return row, f"has an empty {name}"
    try:
        row["seed"] = int(row["seed"])
    except ValueError:
        return row, f"has seed {row['seed'][:20]!r}, not a whole number"
    if row["seed"] < 0:
        return row, "has a negative seed"
    if row["status"] not in STATUSES:
        return row, f"has an unknown status {row['status'][:20]!r}"
    for name in swept_columns(row):  # part of the key: must read back as the value that ran
        try:
            row[name] = float(row[name])
        except ValueError:
            return row, f"holds {row[name][:20]!r} in the swept column {name}"
        if not math.isfinite(row[name]):
            return row, f"has no value in the swept column {name}"
        row[name] = _swept_kind(name)(row[name])  # a swept integer stays an integer
    for name in NUMERIC_COLUMNS:
        if name in row:
            try:
                row[name] = float(row[name]) if row[name] != "" else math.nan
            except ValueError:
                return row, f"holds {row[name][:20]!r} in the numeric column {name}"
    if row["status"] == "ok" and not any(math.isfinite(row.get(c, math.nan)) for c in SCORE_COLUMNS):
        return row, "is 'ok' without an RMS error or a truth-free score"
    return row, None


def warn_native_numerics() -> None:
    """One line when this process cannot give rows that re-run to the last bit elsewhere."""
    from rippleb import numerics

    state = numerics.state()
    if state != numerics.PORTABLE:
        why = (f"{numerics.NATIVE_SWITCH} is set" if numerics.native_requested()
               else "numpy was imported before rippleb")
        warnings.warn(RunWarning(f"the rows run the host's own numeric paths ({state}; {why}): "
                                 "they may differ in their last bits from the same rows on another "
                                 "CPU (docs/reproducibility.md)"), stacklevel=3)


def warn_native_rows(rows: list[dict]) -> None:
    """One line when rows that ran elsewhere (Dask workers) used their host's own paths."""
    from rippleb import numerics

    native = [row["numerics"] for row in rows if row.get("numerics", numerics.PORTABLE) != numerics.PORTABLE]
    if native:
        warnings.warn(RunWarning(f"{len(native)} rows ran on workers with their host's own numeric "
                                 f"paths ({native[0]}): start 'dask worker' with the variables of "
                                 "docs/scale.md so that they re-run to the last bit elsewhere"),
                      stacklevel=3)
