"""gear-keeping paired per device against the other methods of one or more runs.

For each condition (and each value of a swept parameter, in a sweep), each other method's
per-device difference from ``gear-keeping`` (``--method``): ``rms_error_nm`` averaged over
the scenarios every method finished on that device, and ``gear_removed_fraction`` averaged
over the scenarios where it is defined (0.1 Nm RMS of gear torque at least). Statistic: the
report's own paired lead (:func:`rippleb.report.paired.paired_test`, a 95 % t interval,
no Bonferroni correction here: one table per question). Optionally per scenario.

    python docs/tables/gear_keeping_table.py runs/base10 runs/gk10 [--by-scenario]
    python docs/tables/gear_keeping_table.py runs/te_sweep

docs/methods/gear-keeping.md copies the tables and gives the commands that made the runs.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd

from rippleb.report.paired import paired_test

COLUMNS = ("rms_error_nm", "gear_removed_fraction")


def read_runs(paths) -> pd.DataFrame:
    """The ok rows of every run directory (or results CSV) in ``paths``, checked."""
    from rippleb.engine.results import read_rows

    rows = []
    for path in paths:
        path = Path(path)
        rows += read_rows(path / "results.csv" if path.is_dir() else path)
    frame = pd.DataFrame(rows)
    return frame[frame["status"] == "ok"]


def paired_table(frame: pd.DataFrame, method: str = "gear-keeping", by_scenario: bool = False) -> pd.DataFrame:
    """One row per (group, other method): for each column, the mean of ``other - method``
    over the devices, its 95 % half-width and on how many devices ``method`` is lower. The
    group is the condition, the swept values and, with ``by_scenario``, the scenario."""
    swept = [c for c in frame.columns if "." in c and c not in COLUMNS]
    keys = ["condition"] + swept + (["scenario"] if by_scenario else [])
    out = []
    for group, rows in frame.groupby(keys, sort=True):
        group = group if isinstance(group, tuple) else (group,)
        per_device = {}
        for column in COLUMNS:
            values = rows if column == "rms_error_nm" else rows[rows["gear_torque_rms_nm"] >= 0.1]
            per_device[column] = values.groupby(["method", "seed"])[column].mean().unstack(0)
        if method not in per_device["rms_error_nm"]:
            continue
        for other in sorted(set(rows["method"]) - {method}):
            record = dict(zip(keys, group), method=other)
            for column, table in per_device.items():
                if other not in table or method not in table:
                    continue
                lead = paired_test(table[method], table[other])
                record.update({f"{column}": lead.mean, f"{column}_half": lead.half,
                               f"{column}_lower": f"{lead.wins}/{lead.n}"})
            out.append(record)
    return pd.DataFrame(out)


def markdown(table: pd.DataFrame, method: str = "gear-keeping") -> str:
    """The table in Markdown: ``other - method`` per column (positive: ``method`` lower)."""
    keys = [c for c in table.columns if c not in ("method",) and not c.startswith(COLUMNS)]
    head = keys + ["other method", f"rms_error_nm: other - {method} [Nm]",
                   f"gear_removed_fraction: other - {method}"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for _, row in table.iterrows():
        cells = [f"{row[k]:g}" if isinstance(row[k], float) else str(row[k]) for k in keys] + [f"`{row['method']}`"]
        for column in COLUMNS:
            if column in row and np.isfinite(row[column]):
                cells.append(f"{row[column]:+.3f} ± {row[column + '_half']:.3f} ({method} lower on "
                             f"{row[column + '_lower']})")
            else:
                cells.append("n/a")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", help="run directories (or results.csv files)")
    parser.add_argument("--method", default="gear-keeping", help="the method the others are paired with")
    parser.add_argument("--by-scenario", action="store_true", help="one row per scenario too")
    args = parser.parse_args(argv)
    frame = read_runs(args.runs)
    print(markdown(paired_table(frame, args.method, args.by_scenario), args.method))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
