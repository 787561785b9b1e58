"""``rippleb report``: the comparison of a run, generated from its ``results.csv``.

``rippleb report DIR [--out OUT] [--published] [--html]`` writes ``README.md`` (the method x
condition summary and headline, the gauge layouts of a layout sweep, then per condition the
method x scenario matrices as mean and 95 % t-interval over seeds, the timing table, a ranking
per scenario and the paper's Table I replica; the rows that did not finish ok; provenance),
every row as ``results.csv``, ``provenance.json``, the figures of :mod:`rippleb.report.figures`
and, with ``--html``, the interactive ``index.html`` of :mod:`rippleb.report.html_report`.
Tables live in :mod:`rippleb.report.tables`, statistics in :mod:`rippleb.report.stats`, provenance
in :mod:`rippleb.report.provenance`; this module reads the rows and writes the files. The names
used by earlier versions of this module are re-exported here.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np

from rippleb.errors import InputError
from rippleb.files import atomic_path, refuse_links
from rippleb.report.provenance import (collect_provenance, environment_sentence, environment_warnings, git_state,
                                       provenance_markdown,  # noqa: F401
                                       read_run_provenance, seeds_text)
from rippleb.scoring.metrics import METRIC_COLUMNS
from rippleb.scoring.truthfree import TRUTH_FREE_COLUMNS
from rippleb.engine.results import RunWarning, copy_rows, row_key, swept_columns
from rippleb.engine.sealing import sealed_rows, sealed_text
from rippleb.report.publication import SALT_NAME, compare_rows, read_results_exact  # noqa: F401 - re-exported
from rippleb.report.sections import READING_RECORDED, READING_SIMULATED, conditions_note, summary_sections  # noqa: F401
from rippleb.report.tuning_table import tuning_markdown
from rippleb.report.stats import (CONFIDENCE, METHOD_ORDER, fmt_interval, interval_frame,  # noqa: F401
                                  method_order, scenario_order, t_interval, with_condition)
from rippleb.report.table_one import (PAPER_CITATION, PAPER_TABLE_I, TABLE_I_METHODS,  # noqa: F401
                                      TABLE_I_SCENARIO, table_one, table_one_markdown)
from rippleb.report.tables import (ACCURACY_COLUMNS, MATRIX_COLUMNS, by_condition,  # noqa: F401
                                   counts_sentence, is_recorded, title_lines,
                                   condition_headline, condition_summary, condition_summary_markdown,
                                   failed_markdown, headline_lines, headline_sentences, matrix_markdown, plural,
                                   ranking, ranking_markdown, summary_text, timing_markdown, timing_note)

def load_rows(run_dir):
    """The rows of ``run_dir/results.csv`` as a DataFrame; one-line error if there are none."""
    from rippleb.integrity import verified_rows
    from rippleb.engine.results import ResultsFile, read_rows

    run_dir = Path(run_dir)
    path = run_dir / "results.csv"
    if not (path.is_symlink() or path.exists()):   # a link, a FIFO: the reader says what it is
        raise InputError(f"{run_dir}: no results.csv (is this a rippleb run directory?)")
    results = ResultsFile(None)
    results.rows = verified_rows(run_dir, read_rows(path), path)
    frame = results.frame()
    if frame.empty:
        raise InputError(f"{path}: no rows to report")
    _warn_implausible(frame, path)
    return frame


def frame_condition_count(frame) -> int:
    """How many deployment conditions the rows hold (a file without the column: one)."""
    return int(frame["condition"].nunique()) if "condition" in frame else 1


#: Metrics that no row can hold below zero (``step_latency_ms`` can: an estimate may lead).
NON_NEGATIVE = tuple(c for c in METRIC_COLUMNS if c not in ("step_latency_ms", "gear_removed_fraction")) + \
    ("ripple_wg_nm", "rest_std_nm")


def _warn_implausible(frame, path) -> None:
    """One warning line naming the rows whose metrics no run writes: negative where the
    metric cannot be (an RMS error), or infinite (n/a is empty, never inf). The rows are
    kept and reported as they are: the file says so, the report must not hide it."""
    bad = []
    for column in METRIC_COLUMNS + TRUTH_FREE_COLUMNS:
        if column not in frame:
            continue
        values = frame[column].astype(float)
        wrong = np.isinf(values) | ((values < 0) if column in NON_NEGATIVE else False)
        for i in np.flatnonzero(np.asarray(wrong)):
            row = frame.iloc[i]
            bad.append(f"{row['method']}/{row['scenario']}/{row['condition']}/seed {row['seed']} "
                       f"{column} = {values.iloc[i]:g}")
    if bad:
        warnings.warn(f"{path}: {len(bad)} metric value(s) that no rippleb run writes (negative or "
                      f"infinite; edited or corrupted?), reported as they are: {'; '.join(bad[:3])}"
                      f"{'; ...' if len(bad) > 3 else ''}", RunWarning, stacklevel=3)


def tables_markdown(frame, joint: dict | None = None) -> str:
    """The README's tables and their sentences: a pure function of the rows, so
    ``tests/test_published.py`` can regenerate it and find it in ``results/README.md``.
    A recorded log has its own (:mod:`rippleb.report.recorded`; ``joint``: its joint as
    ``run.json`` records it)."""
    if is_recorded(frame):
        from rippleb.report.recorded import recorded_tables_markdown

        return recorded_tables_markdown(frame, joint)
    source = "Recorded" if is_recorded(frame) else "Simulated"
    parts = summary_sections(frame)
    for condition, rows in by_condition(frame):
        parts += _condition_section(condition, rows, source)
    parts += ["## Rows that did not finish ok", "", failed_markdown(frame)]
    return "\n".join(parts)


def _condition_section(condition: str, rows, source: str) -> list[str]:
    from rippleb.simulator.conditions import CONDITIONS

    from rippleb.printable import markdown_code, markdown_text

    what = CONDITIONS.get(condition, "not a built-in condition")
    parts = [f"## Condition {markdown_code(condition)}: {what}", ""]
    parts += [f"- {s}" for s in headline_sentences(rows)] + [""]
    for column, (title, unit) in MATRIX_COLUMNS.items():
        if column in rows and rows[column].notna().any():  # older rows, or n/a everywhere
            parts += [f"### `{column}`: {title} [{unit}] ({markdown_text(condition)})", "",
                      matrix_markdown(rows, column), ""]
    if "us_per_tick_p99" in rows:
        parts += [f"### Compute time of one control tick, p50 / p99 [us] ({markdown_text(condition)})", "",
                  timing_markdown(rows), ""]
    parts += [f"### Ranking per scenario by `rms_error_nm` ({markdown_text(condition)})", "", ranking_markdown(rows), ""]
    parts += [f"### The paper's Table I, replicated ({markdown_text(condition)})", "",
              table_one_markdown(rows, source), ""]
    return parts


def load_sweep(path):
    """The rows of a sweep for "Where each conclusion holds" (``--sweep``): a run directory
    of ``rippleb sweep`` or a report written from one; one line when it holds no swept column."""
    rows = load_rows(path)
    if not swept_columns(rows.columns):
        raise InputError(f"--sweep {path}: no swept parameter in its rows (a 'rippleb sweep' run, or its report, "
                         f"is what --sweep reads)")
    return rows


def holds_markdown(frame, sweeps) -> str:
    """The section "Where each conclusion holds" of ``frame``'s report over ``sweeps``
    (``[(name, rows)]``), as the README prints it: a pure function of the rows, so
    ``tests/test_published.py`` regenerates it."""
    from rippleb.report.holds import blocks_markdown, holds_blocks

    return blocks_markdown(holds_blocks(frame, sweeps))


def readme_markdown(frame, prov: dict, figures: dict, *, published: bool = False,
                    run_dir: str = "DIR", sweeps=()) -> str:
    """``README.md`` of a report: every number from ``frame`` or ``prov``.

    ``published`` is True only for the comparison in the repository's ``results/``
    (``rippleb report ... --published``): only then does the title say so.
    """
    recorded = is_recorded(frame)
    parts = title_lines(published, recorded, run_dir) + ["", counts_sentence(frame, recorded),
                                                         "", environment_sentence(prov.get("run", {}))]
    note = conditions_note(frame)
    parts += ["", note] if note else []
    if not recorded:
        parts += ["", prov.get("sealed") or sealed_text(frame, prov.get("run", {}))]
    parts += ["", READING_RECORDED if recorded else READING_SIMULATED]
    parts += ["", tables_markdown(frame, prov.get("run", {}).get("joint"))]
    if sweeps and not recorded:
        parts += ["", holds_markdown(frame, sweeps)]
    if not recorded:
        parts += ["", "## How each method was tuned", "",
                  tuning_markdown(prov.get("run", {}).get("tuning"), method_order(frame["method"]))]
    if "us_per_tick_p99" in frame:
        parts += ["", "## How timing was taken", "", timing_note(prov, frame)]
    if figures:
        parts += ["", "## Figures", ""]
        for name, (path, caption) in figures.items():
            parts += [f"### {caption}", "", f"![{name}](figures/{path.name})", ""]
    parts += ["", "## Provenance", "", provenance_markdown(prov), ""]
    return "\n".join(parts)


def report(run_dir, out=None, *, figures: bool = True, figure_seed: int = 0, argv=None,
           published: bool = False, html: bool = False, figure_format: str = "png",
           speed_seeds: int | None = None, salt_file=None, sweeps=()) -> dict:
    """Write the report of ``run_dir`` into ``out`` (default ``run_dir/report``).

    Parameters
    ----------
    run_dir
        A directory written by ``rippleb run`` (``results.csv``, ``run.json``,
        ``provenance.json``).
    out
        Output directory: ``README.md``, ``results.csv``, ``provenance.json``, ``figures/``
        and, with ``html``, ``index.html``.
    figures
        Also draw the figures (those with signals re-simulate ``figure_seed``).
    argv
        The command line of the report, for the provenance (default ``sys.argv[1:]``).
    published
        Title and caveats of the project's published comparison (``results/``).
    html
        Also write the self-contained interactive ``index.html``.
    figure_format
        ``png``, ``svg`` or ``pdf``.
    speed_seeds
        The error-against-speed figure averages the first ``speed_seeds`` seeds of the run
        (default: all of them; each is re-simulated and re-streamed).
    salt_file
        The salt of a sealed run (the file ``rippleb run --sealed`` wrote), to publish beside
        the report as ``OUT/salt.txt`` once checked against the run's commitment
        (:mod:`rippleb.report.publication`); ``out`` must then lie outside ``run_dir``.
    sweeps
        Directories of sweep rows (``rippleb sweep`` runs, or the reports written from
        them) on which the report's conclusions are re-evaluated: the section "Where each
        conclusion holds" (:mod:`rippleb.report.holds`).

    Returns
    -------
    dict
        ``{"readme": path, "csv": path, "provenance": path, "html": path or None,
        "figures": {name: path}, "warnings": [...]}``
    """
    run_dir = Path(run_dir)
    frame = load_rows(run_dir)
    if out is None:   # the run directory's own entry: never a link (one to elsewhere would take the report there)
        refuse_links(run_dir, ["report"])
    out = Path(out) if out is not None else run_dir / "report"
    salt = None
    if salt_file is not None:
        from rippleb.engine.sealing import published_salt
        from rippleb.report.publication import check_salt_destination

        check_salt_destination(run_dir, out)
        salt = published_salt(read_run_provenance(run_dir), salt_file)
    swept = [(str(path), load_sweep(path)) for path in sweeps]
    _mkdir(out)
    refuse_links(out, REPORT_ENTRIES, also_in="figures")
    try:
        return _write_report(run_dir, out, frame, figures=figures, figure_seed=figure_seed, argv=argv,
                             published=published, html=html, figure_format=figure_format,
                             speed_seeds=speed_seeds, salt=salt, sweeps=swept)
    except OSError as exc:  # a full disk or a quota while writing figures: one line, not a traceback
        raise InputError(f"{exc.filename or out}: cannot write the report: {exc.strerror or exc}") from None


def _write_report(run_dir: Path, out: Path, frame, *, figures, figure_seed, argv, published, html,
                  figure_format, speed_seeds, salt=None, sweeps=()) -> dict:
    prov = {"run": read_run_provenance(run_dir), "report": collect_provenance(argv),
            "published": published, "seeds": sorted(int(s) for s in frame["seed"].unique()),
            "seeds_text": seeds_text(frame["seed"].unique()), "rows": len(frame),
            "statuses": {k: int(v) for k, v in frame["status"].value_counts().items()}}
    for col in ("rippleb_version", "python", "cpu"):
        values = sorted(str(v) for v in frame[col].dropna().unique()) if col in frame else []
        prov[f"rows_{col}"] = ", ".join(values) or "not recorded"
    prov["run_dir"] = str(run_dir)
    prov["sweeps"] = [{"dir": name, "rows": len(rows)} for name, rows in sweeps]
    prov["sealed"] = sealed_text(frame, prov["run"])
    if salt is not None:
        from rippleb.report.publication import verify_text, write_salt

        prov["salt"] = write_salt(out, salt)
        prov["sealed"] += " " + verify_text(prov["salt"])
    drawn, warnings, signals = {}, environment_warnings(frame, prov["run"]), {}
    if prov["sealed"].startswith("Partly"):
        warnings.append(prov["sealed"])
    if figures and swept_columns(frame.columns):
        # a sweep is read through error against each swept parameter; the signal figures
        # would show the built-in scenarios at values the sweep did not hold fixed
        from rippleb.report.sweep_report import figures as sweep_figures

        drawn = sweep_figures(frame, out / "figures")
    elif figures:
        from rippleb.report import figures as figs

        seeds = sorted(int(s) for s in frame["seed"].unique())
        drawn, figure_warnings = figs.draw_all(frame, out / "figures", seed=figure_seed, fmt=figure_format,
                                        speed_seeds=seeds[:speed_seeds] if speed_seeds else seeds,
                                        keep=signals, sealed=sealed_rows(frame) > 0)
        warnings += figure_warnings
    prov["figure_seed"] = figure_seed if figures else None
    # A byte copy, not a rewrite: re-printing parsed floats could change their last digit,
    # and tests/test_published.py compares them exactly. Only of the rows reported: those
    # a reader dropped (not rippleb's, or cut short) stay out of the copy too.
    with atomic_path(out / "results.csv") as tmp:
        copy_rows(run_dir / "results.csv", tmp, {row_key(r) for r in frame.to_dict("records")})
    _write(out / "provenance.json", json.dumps(prov, indent=1, default=str) + "\n")
    _write(out / "README.md", readme_markdown(frame, prov, drawn, published=published, run_dir=str(run_dir),
                                              sweeps=sweeps))
    page = None
    if html:
        from rippleb.report.html_report import write_html

        page = write_html(frame, prov, out / "index.html", figure_seed=figure_seed if figures else None,
                          signals=signals, sweeps=sweeps)
    return {"readme": out / "README.md", "csv": out / "results.csv", "provenance": out / "provenance.json",
            "html": page, "figures": {k: v[0] for k, v in drawn.items()}, "warnings": warnings}


#: What ``rippleb report`` writes in its directory; none may be a symbolic link (nor anything in figures/).
REPORT_ENTRIES = ("README.md", "results.csv", "provenance.json", "index.html", SALT_NAME, "figures")


def _mkdir(path: Path) -> None:
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"{path}: cannot write: {exc.strerror or exc}") from None


def _write(path: Path, text: str) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(text)
