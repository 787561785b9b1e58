"""What moved between two runs: mean error per method and condition, and the rankings.

    python benchmarks/compare_runs.py results/results.csv runs/published/results.csv
    python benchmarks/compare_runs.py --spread before.csv after.csv

``--spread`` measures how far two runs of the same rows are apart when only the last bits of
the arithmetic differ (another CPU's numeric paths, docs/reproducibility.md): how many rows
are bit for bit equal, the relative difference of each accuracy column per row, and the
difference of each cell's mean over seeds against its 95 % interval.

Reads two ``results.csv`` files (for instance the published table before a change of the
simulator and the run after it) and prints Markdown tables: the mean ``rms_error_nm`` and
``max_error_nm`` of each method under each condition (over every scenario and seed both runs
share), the rank of each method per condition in each run, and the per-scenario change of
every method whose rank moved. Use it to explain a ranking change by its mechanism.
"""

from __future__ import annotations

import sys

import rippleb  # noqa: F401 - before numpy: the portable numeric paths (rippleb/numerics.py)

import pandas as pd

KEY = ["method", "scenario", "condition", "seed"]


def load(path: str) -> pd.DataFrame:
    frame = pd.read_csv(path)
    frame = frame[frame["status"] == "ok"]
    if "condition" not in frame:
        frame["condition"] = "same-session"
    return frame


def common_rows(before: pd.DataFrame, after: pd.DataFrame) -> tuple[pd.DataFrame, pd.DataFrame]:
    keys = before[KEY].merge(after[KEY], on=KEY)
    return before.merge(keys, on=KEY), after.merge(keys, on=KEY)


def by_condition(frame: pd.DataFrame, column: str) -> pd.DataFrame:
    return frame.groupby(["method", "condition"])[column].mean().unstack("condition")


def arrows(a: pd.DataFrame, b: pd.DataFrame, fmt: str) -> pd.DataFrame:
    """Cells ``a -> b``."""
    b = b.reindex(index=a.index, columns=a.columns)
    cells = [[f"{fmt.format(u)} -> {fmt.format(v)}" for u, v in zip(ra, rb)]
             for ra, rb in zip(a.to_numpy(), b.to_numpy())]
    return pd.DataFrame(cells, index=a.index, columns=a.columns)


def compare(before_path: str, after_path: str) -> str:
    before, after = common_rows(load(before_path), load(after_path))
    parts = [f"{len(before)} rows in both runs\n"]
    for column in ("rms_error_nm", "max_error_nm"):
        a, b = by_condition(before, column), by_condition(after, column)
        parts.append(f"## mean {column} (before -> after)\n\n" + arrows(a, b, "{:.3f}").to_markdown() + "\n")
    ranks_before = by_condition(before, "rms_error_nm").rank()
    ranks_after = by_condition(after, "rms_error_nm").rank()
    moved = (ranks_before != ranks_after).any(axis=1)
    parts.append("## rank by mean rms_error_nm (1 = best; before -> after)\n\n"
                 + arrows(ranks_before, ranks_after, "{:.0f}").to_markdown() + "\n")
    if moved.any():
        per_scenario = pd.concat({
            "before": before.groupby(["method", "scenario"])["rms_error_nm"].mean(),
            "after": after.groupby(["method", "scenario"])["rms_error_nm"].mean()}, axis=1)
        per_scenario["ratio"] = per_scenario["after"] / per_scenario["before"]
        movers = per_scenario.loc[list(moved[moved].index)]
        parts.append("## methods whose rank moved: mean rms_error_nm per scenario, all conditions\n\n"
                     + movers.round(3).to_markdown() + "\n")
    return "\n".join(parts)


def spread(before_path: str, after_path: str) -> str:
    from rippleb.report.stats import interval_frame
    from rippleb.report.tables import ACCURACY_COLUMNS

    before, after = common_rows(load(before_path), load(after_path))
    before, after = before.sort_values(KEY).reset_index(drop=True), after.sort_values(KEY).reset_index(drop=True)
    columns = [c for c in ACCURACY_COLUMNS if c != "n_samples"]
    same = pd.concat([(before[c] == after[c]) | (before[c].isna() & after[c].isna()) for c in columns], axis=1)
    parts = [f"{len(before)} rows in both runs; {int(same.all(axis=1).sum())} equal bit for bit in every "
             "accuracy column\n", "## relative difference per row, |after - before| / |before|\n"]
    records = []
    for c in columns:
        rel = ((after[c] - before[c]).abs() / before[c].abs()).dropna()
        records.append({"column": c, "rows differing": int((rel > 0).sum()), "median": rel.median(),
                        "95th percentile": rel.quantile(0.95), "max": rel.max()})
    parts.append(pd.DataFrame(records).to_markdown(index=False, floatfmt=".2g") + "\n")
    cells = interval_frame(before, "rms_error_nm", by=("method", "scenario", "condition"))
    moved = interval_frame(after, "rms_error_nm", by=("method", "scenario", "condition"))
    cells = cells.merge(moved, on=["method", "scenario", "condition"], suffixes=("", "_after"))
    ratio = (cells["mean_after"] - cells["mean"]).abs() / cells["half"]
    parts.append("## cell means (method x scenario x condition, rms_error_nm over seeds)\n\n"
                 f"{len(cells)} cells; |mean after - mean before| / 95 % half-width: median "
                 f"{ratio.median():.3g}, 95th percentile {ratio.quantile(0.95):.3g}, max {ratio.max():.3g} "
                 f"({cells.loc[ratio.idxmax(), ['method', 'scenario', 'condition']].tolist()}); "
                 f"relative change of the mean: max "
                 f"{((cells['mean_after'] - cells['mean']).abs() / cells['mean']).max():.3g}\n")
    return "\n".join(parts)


if __name__ == "__main__":
    if len(sys.argv) == 4 and sys.argv[1] == "--spread":
        print(spread(sys.argv[2], sys.argv[3]))
    elif len(sys.argv) == 3:
        print(compare(sys.argv[1], sys.argv[2]))
    else:
        sys.exit(__doc__.split("\n\n")[1].strip())
