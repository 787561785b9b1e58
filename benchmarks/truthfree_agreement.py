"""How well each truth-free ranking agrees with the true one, on simulated logs.

Runs every built-in method on every scored scenario under every condition for a few
seeds (``rippleb.run``, the same rows as the CLI), then per case (condition, scenario,
seed) ranks the methods by each truth-free column (``rippleb/truthfree.py``; the delay by
its absolute value: a lead is no better than a lag) and by ``rms_error_ref_nm`` (what a
log with a reference is ranked by), and compares each ranking with the true one
(``rms_error_nm`` against ``torque_true``) by Spearman's rho and Kendall's tau-b
(``scipy.stats``). Prints per condition the mean of each over the cases where both rankings
are defined (at least 3 methods with a finite value), as the Markdown table of
``docs/metrics.md``.

    python benchmarks/truthfree_agreement.py --seeds 2 --jobs 1 --out runs/truthfree
    python benchmarks/truthfree_agreement.py --rows runs/truthfree/results.csv   # table only
"""

import rippleb  # noqa: F401 - before numpy: the portable numeric paths (rippleb/numerics.py)

import argparse

import numpy as np
import pandas as pd
from scipy import stats

from rippleb.report.stats import condition_order
from rippleb.truthfree import TRUTH_FREE_COLUMNS

TRUE = "rms_error_nm"
MEASURES = TRUTH_FREE_COLUMNS + ("rms_error_ref_nm",)
#: Fewer ranked methods than this make a rank correlation meaningless.
MIN_METHODS = 3


def case_agreement(rows: pd.DataFrame, measure: str) -> tuple[float, float]:
    """Spearman's rho and Kendall's tau between ``measure`` and the true error over the ok
    rows of one case; NaN where either is undefined."""
    ok = rows[rows["status"] == "ok"]
    values = ok[measure].abs() if measure == "strain_delay_ms" else ok[measure]
    keep = np.isfinite(values.to_numpy(float)) & np.isfinite(ok[TRUE].to_numpy(float))
    if keep.sum() < MIN_METHODS:
        return float("nan"), float("nan")
    x, y = values[keep].to_numpy(float), ok[TRUE][keep].to_numpy(float)
    if np.ptp(x) == 0 or np.ptp(y) == 0:
        return float("nan"), float("nan")
    return float(stats.spearmanr(x, y).statistic), float(stats.kendalltau(x, y).statistic)


def agreement_table(frame: pd.DataFrame) -> str:
    """Per condition and measure: mean rho / mean tau over the cases, and how many cases."""
    lines = ["| condition | " + " | ".join(f"`{m}` rho / tau (cases)" for m in MEASURES) + " |",
             "|---|" + "---:|" * len(MEASURES)]
    for condition in condition_order(frame["condition"].unique()):
        rows = frame[frame["condition"] == condition]
        cells = []
        for measure in MEASURES:
            pairs = np.array([case_agreement(case, measure)
                              for _, case in rows.groupby(["scenario", "seed"])])
            defined = pairs[np.isfinite(pairs[:, 0])]
            cells.append("n/a (0)" if len(defined) == 0 else
                         f"{defined[:, 0].mean():+.2f} / {defined[:, 1].mean():+.2f} ({len(defined)})")
        lines.append(f"| {condition} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=2, help="devices per condition (default 2)")
    parser.add_argument("--jobs", type=int, default=1, help="rows at once (default 1)")
    parser.add_argument("--out", help="run directory to keep the rows in (default: memory only)")
    parser.add_argument("--rows", help="a results.csv to read instead of running")
    args = parser.parse_args()
    if args.rows:
        frame = pd.read_csv(args.rows)
    else:
        frame = rippleb.run(seeds=args.seeds, conditions="all", jobs=args.jobs, out=args.out)
    print(f"{len(frame)} rows, {frame['seed'].nunique()} seeds, "
          f"{frame['scenario'].nunique()} scenarios, {frame['method'].nunique()} methods\n")
    print(agreement_table(frame))


if __name__ == "__main__":
    main()
