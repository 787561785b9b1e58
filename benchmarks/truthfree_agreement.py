"""How well each truth-free ranking agrees with the true one, on simulated logs.

Runs every built-in method on every scored scenario under every condition for a few
seeds (``rippleb.run``, the same rows as the CLI), then per case (condition, scenario,
seed) ranks the methods by each truth-free column (``rippleb/scoring/truthfree.py``; the delay by
its absolute value: a lead is no better than a lag) and by ``rms_error_ref_nm`` (what a
log with a reference is ranked by), and compares each ranking with the true one
(``rms_error_nm`` against ``torque_true``) by Spearman's rho and Kendall's tau-b
(``scipy.stats``). Prints per condition the mean of each over the cases where both rankings
are defined (at least 3 methods with a finite value), as the Markdown table of
``docs/metrics.md``; then the same without the methods that do not read the strain, and
per scenario over every condition.

    python benchmarks/truthfree_agreement.py --seeds 2 --seed-start 3100 --jobs 1 --out runs/truthfree
    python benchmarks/truthfree_agreement.py --rows runs/truthfree/results.csv   # table only

Use devices no method was developed on (``--seed-start 3100``: the public seeds 0-99 are the
development devices).
"""

import rippleb  # noqa: F401 - before numpy: the portable numeric paths (rippleb/numerics.py)

import argparse

import numpy as np
import pandas as pd
from scipy import stats

from rippleb.report.stats import condition_order, scenario_order
from rippleb.scoring.truthfree import TRUTH_FREE_COLUMNS

TRUE = "rms_error_nm"
MEASURES = TRUTH_FREE_COLUMNS + ("rms_error_ref_nm",)
#: Methods whose estimate does not come from the strain: the truth-free columns see little of
#: what is wrong with them (a friction or inertia error is not ripple), so the agreement is
#: also given without them.
NOT_FROM_STRAIN = ("current-based",)
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


def agreement_table(frame: pd.DataFrame, by: str = "condition") -> str:
    """Per ``by`` (condition or scenario) and measure: mean rho / mean tau over the cases
    (condition, scenario, seed), and how many cases."""
    order = condition_order if by == "condition" else scenario_order
    lines = [f"| {by} | " + " | ".join(f"`{m}` rho / tau (cases)" for m in MEASURES) + " |",
             "|---|" + "---:|" * len(MEASURES)]
    for name in order(frame[by].unique()):
        rows = frame[frame[by] == name]
        cells = []
        for measure in MEASURES:
            pairs = np.array([case_agreement(case, measure)
                              for _, case in rows.groupby(["condition", "scenario", "seed"])])
            defined = pairs[np.isfinite(pairs[:, 0])]
            cells.append("n/a (0)" if len(defined) == 0 else
                         f"{defined[:, 0].mean():+.2f} / {defined[:, 1].mean():+.2f} ({len(defined)})")
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=2, help="devices per condition (default 2)")
    parser.add_argument("--seed-start", type=int, default=3100, help="first device (default 3100: fresh devices)")
    parser.add_argument("--jobs", type=int, default=1, help="rows at once (default 1)")
    parser.add_argument("--out", help="run directory to keep the rows in (default: memory only)")
    parser.add_argument("--rows", help="a results.csv to read instead of running")
    args = parser.parse_args()
    if args.rows:
        frame = pd.read_csv(args.rows)
    else:
        frame = rippleb.run(seeds=args.seeds, seed_start=args.seed_start, conditions="all", jobs=args.jobs,
                            out=args.out)
    print(f"{len(frame)} rows, {frame['seed'].nunique()} seeds, "
          f"{frame['scenario'].nunique()} scenarios, {frame['method'].nunique()} methods\n")
    print(agreement_table(frame))
    print(f"\nThe same without {', '.join(NOT_FROM_STRAIN)} (methods that do not read the strain):\n")
    print(agreement_table(frame[~frame["method"].isin(NOT_FROM_STRAIN)]))
    print("\nThe same per scenario, over every condition:\n")
    print(agreement_table(frame, by="scenario"))


if __name__ == "__main__":
    main()
