"""The figures of a sensitivity sweep: the error against each swept parameter.

One figure per swept column (:func:`rippleb.engine.results.swept_columns`): the RMS error against
the simulated true torque, mean over seeds with its 95 % Student-t interval
(:func:`rippleb.report.writer.t_interval`), against the parameter's value, one line per method,
one panel per deployment condition and scored scenario. Where several parameters were
swept together, each combination of the other parameters' values is its own line style.
Only ``ok`` rows count; a point with fewer than two seeds has no interval.
"""

from __future__ import annotations

import itertools
from pathlib import Path

from rippleb.engine.params import PARAMS
from rippleb.engine.results import swept_columns

ERROR_COLUMN = "rms_error_nm"
LINESTYLES = ("-", "--", ":", "-.")
LOG_SCALE = {"joint.counts_per_rev", "joint.fs", "joint.control_rate"}  # spans of decades


def figures(frame, out_dir) -> dict:
    """Draw the figure of each swept column of ``frame`` into ``out_dir``.

    Returns
    -------
    dict
        ``{name: (path, caption)}``, empty when the rows hold no swept column.
    """
    drawn = {}
    for column in swept_columns(frame.columns):
        if frame[column].notna().any():
            path = _plot(frame, column, Path(out_dir))
            drawn[f"sweep-{column}"] = (path, f"RMS error against {column} (mean over seeds, 95 % interval)")
    return drawn


def write(frame, out_dir) -> list[Path]:
    """The paths of the figures :func:`figures` writes."""
    return [path for path, _ in figures(frame, out_dir).values()]


def points(frame, column: str):
    """Per (condition, scenario, method, other swept values, value of ``column``): mean,
    95 % half-width and number of seeds of the RMS error over the ``ok`` rows."""
    import pandas as pd

    from rippleb.report.stats import t_interval

    others = [c for c in swept_columns(frame.columns) if c != column]
    ok = frame[frame["status"] == "ok"]
    groups = ["condition", "scenario", "method", *others, column]
    rows = []
    for key, group in ok.groupby(groups, sort=True):
        mean, half, n = t_interval(group[ERROR_COLUMN])
        rows.append({**dict(zip(groups, key)), "mean": mean, "half": half, "n": n})
    return pd.DataFrame(rows, columns=[*groups, "mean", "half", "n"])


def _plot(frame, column: str, out_dir: Path) -> Path:
    from rippleb.report.plotting import _pyplot, _save, plot_text, style

    plt = _pyplot()
    table = points(frame, column)
    panels = sorted(set(zip(table["condition"], table["scenario"]))) or [("", "")]
    others = [c for c in swept_columns(frame.columns) if c != column]
    fig, axes = plt.subplots(1, len(panels), figsize=(4.2 * len(panels) + 1.0, 3.6), squeeze=False,
                             sharey=True)
    for ax, (condition, scenario) in zip(axes[0], panels):
        panel = table[(table["condition"] == condition) & (table["scenario"] == scenario)]
        for i, (method, lines) in enumerate(panel.groupby("method", sort=True)):
            combos = lines.groupby(others, sort=True) if others else [((), lines)]
            for style_i, (combo, line) in zip(itertools.count(), combos):
                combo = combo if isinstance(combo, tuple) else (combo,)
                kw = style(method, i, points=True)
                kw["ls"] = LINESTYLES[style_i % len(LINESTYLES)] if others else kw["ls"]
                if others:
                    kw["label"] = f"{plot_text(method)} ({', '.join(f'{c}={v:g}' for c, v in zip(others, combo))})"
                ax.errorbar(line[column], line["mean"], yerr=line["half"].fillna(0.0), ms=3, capsize=3, **kw)
        if column in LOG_SCALE:
            ax.set_xscale("log")
        choices = PARAMS[column].choices if column in PARAMS else ()
        if choices:   # a layout: its position in the list, labelled by its name
            shown = sorted(int(v) for v in table[column].unique())
            ax.set_xticks(shown, [PARAMS[column].name_of(v) for v in shown], rotation=30, fontsize=7)
        ax.set_yscale("log")
        ax.set_xlabel(column)
        ax.set_title(f"{plot_text(scenario)}, {plot_text(condition)}", fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
    axes[0][0].set_ylabel("RMS error vs true torque [Nm]")
    axes[0][-1].legend(fontsize=7, loc="center left", bbox_to_anchor=(1.02, 0.5))
    fig.tight_layout()
    return _save(fig, out_dir / f"sweep-{_file_part(column)}.png")


def _file_part(column: str) -> str:
    return column.replace(".", "-")
