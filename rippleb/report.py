"""``rippleb report``: a Markdown summary of a run's ``results.csv``.

For now one table, the median over seeds of each method x scenario (a later issue adds
figures and provenance). Medians, because one odd device should not move a published number.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

from rippleb.errors import InputError

SUMMARY_COLUMNS = ("rms_error_nm", "max_error_nm", "rms_error_ref_nm", "delay_ms",
                   "restart_max_error_nm", "stopped_rms_error_nm", "us_per_tick_p50", "us_per_tick_p99")


def summary_markdown(frame) -> str:
    """One row per method x scenario: seeds ok/total, then the median of each column."""
    import pandas as pd

    if len(frame) == 0:
        return "(no rows)"
    ok = frame[frame["status"] == "ok"]
    groups = frame.groupby(["method", "scenario"], sort=True)
    table = pd.DataFrame({"ok": groups["status"].apply(lambda s: f"{(s == 'ok').sum()}/{len(s)}")})
    if len(ok):
        medians = ok.groupby(["method", "scenario"])[list(SUMMARY_COLUMNS)].median()
        table = table.join(medians)
    table = table.reset_index()
    failed = frame[frame["status"] != "ok"]
    text = "Median over seeds of the rows with status ok.\n\n" + table.to_markdown(index=False, floatfmt=".3g")
    if len(failed):
        lines = [f"- {r.method} / {r.scenario} / seed {r.seed}: {r.status}: {r.message}"
                 for r in failed.itertuples()]
        text += "\n\nRows that did not finish ok:\n\n" + "\n".join(lines)
    return text


def report(run_dir, out=None) -> str:
    """Write ``run_dir/summary.md`` (and publish to ``out/``); return the Markdown."""
    from rippleb.results import ResultsFile, read_rows

    run_dir = Path(run_dir)
    path = run_dir / "results.csv"
    if not path.is_file():
        raise InputError(f"{run_dir}: no results.csv (is this a rippleb run directory?)")
    results = ResultsFile(None)
    results.rows = read_rows(path)
    text = "# rippleb summary\n\n" + summary_markdown(results.frame()) + "\n"
    _write(run_dir / "summary.md", text)
    if out is not None:
        out = Path(out)
        try:
            out.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(path, out / "results.csv")
        except OSError as exc:
            raise InputError(f"{out}: cannot write: {exc.strerror or exc}") from None
        _write(out / "summary.md", text)
    return text


def _write(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        tmp.write_text(text)
        os.replace(tmp, path)
    except OSError as exc:
        raise InputError(f"{path}: cannot write: {exc.strerror or exc}") from None
