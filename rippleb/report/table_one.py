"""The paper's Table I, replicated on ``paper-quintic`` beside the paper's own figures.

The only typed numbers of the report are here: the paper's Table I values, which are
citations (:data:`PAPER_TABLE_I`); every other number is computed from result rows.
"""

from __future__ import annotations

import numpy as np

from rippleb.report.stats import PAPER_SCENARIO, fmt_interval, t_interval

TABLE_I_SCENARIO = PAPER_SCENARIO
TABLE_I_METHODS = ("current-based", "order-tracking")

#: Jung, Kim, Koo, Choi, Moon, "Joint Torque Sensor Embedded in Harmonic Drive Using Order
#: Tracking Method for Robotic Application", IEEE/ASME TMECH 22(4), 2017, Table I: error of
#: each measurement against the model torque of eq. (7) over the Fig. 4 trajectory [Nm], and
#: order tracking as a percentage of current-based. Cited, not computed.
PAPER_TABLE_I = {
    "max": {"current-based": 8.2, "order-tracking": 4.8, "ratio_pct": 58.0},
    "rms": {"current-based": 1.4, "order-tracking": 0.9, "ratio_pct": 64.0},
}
PAPER_CITATION = ("Jung, Kim, Koo, Choi and Moon, IEEE/ASME Trans. Mechatronics 22(4), 2017, "
                  "Table I")
#: The rows of the replica: the paper's measure (max or RMS), the column of the result rows
#: that holds it, and its label. The paper scores "during the motion" (0.16-3.79 s of its
#: Fig. 4 move: ``paper-quintic``'s samples with a commanded velocity); the whole scored
#: window, rest before and after included, stands beside it.
ROWS = (("max", "max", "max_error_ref_nm", "Error max, whole log [Nm]"),
        ("rms", "rms", "rms_error_ref_nm", "Error RMS, whole log [Nm]"),
        ("max_motion", "max", "max_error_ref_motion_nm", "Error max, during the motion [Nm]"),
        ("rms_motion", "rms", "rms_error_ref_motion_nm", "Error RMS, during the motion [Nm]"))


def _markdown(rows, headers) -> str:
    from rippleb.report.markdown import markdown

    return markdown(rows, headers)


def _plural(n: int, word: str) -> str:
    return f"{n} {word}{'' if n == 1 else 's'}"


def table_one(frame):
    """The paper's Table I on ``paper-quintic``: max and RMS error against ``torque_ref``
    of current-based and order-tracking (means over seeds), the ratio of the means in %,
    and the paper's figures beside them (rows of one condition); over the whole scored
    window and during the motion (:data:`ROWS`).

    Returns
    -------
    pandas.DataFrame
        Index ``max``, ``rms``, and ``max_motion``, ``rms_motion`` when the rows hold the
        during-the-motion columns (rows written before them do not); columns ``current-based``, ``current-based_half``,
        ``order-tracking``, ``order-tracking_half``, ``ratio_pct`` (ratio of the means),
        ``ratio_pct_seeds`` and ``ratio_pct_half`` (mean and t-interval of the per-seed
        ratio), ``n`` (seeds with both rows ok) and
        ``paper_current-based``, ``paper_order-tracking``, ``paper_ratio_pct``.
        Empty if either method has no ok row on the scenario.
    """
    import pandas as pd

    ok = frame[(frame["status"] == "ok") & (frame["scenario"] == TABLE_I_SCENARIO)]
    cur, order = TABLE_I_METHODS
    records = {}
    for key, measure, column, _ in ROWS:
        if column not in ok or ok[column].isna().all():
            continue   # rows written before the column
        # Paired by seed: the same device under both methods, as in the paper's experiment.
        wide = ok.pivot_table(index="seed", columns="method", values=column, aggfunc="first")
        if cur not in wide or order not in wide:
            return pd.DataFrame()
        wide = wide[[cur, order]].dropna()
        if wide.empty:
            return pd.DataFrame()
        rec = {}
        for m in (cur, order):
            rec[m], rec[f"{m}_half"], _ = t_interval(wide[m])
        rec["ratio_pct"] = 100.0 * rec[order] / rec[cur]
        rec["ratio_pct_seeds"], rec["ratio_pct_half"], _ = t_interval(100.0 * wide[order] / wide[cur])
        rec["n"] = len(wide)
        rec.update({f"paper_{k}": v for k, v in PAPER_TABLE_I[measure].items()})
        records[key] = rec
    return pd.DataFrame.from_dict(records, orient="index")


def table_one_markdown(frame, source: str = "Simulated") -> str:
    """Table I replica beside the paper's, and generated sentences comparing them."""
    table = table_one(frame)
    cur, order = TABLE_I_METHODS
    if table.empty:
        return (f"Not available: the run has no ok rows of both `{cur}` and `{order}` on "
                f"`{TABLE_I_SCENARIO}`.")
    rows = []
    for key, _, _, label in ROWS:
        if key not in table.index:
            continue
        r = table.loc[key]
        rows.append([label, fmt_interval(r[cur], r[f"{cur}_half"]),
                     fmt_interval(r[order], r[f"{order}_half"]),
                     f"{r['ratio_pct']:.0f} %", f"{r[f'paper_{cur}']:g}", f"{r[f'paper_{order}']:g}",
                     f"{r['paper_ratio_pct']:g} %"])
    head = [f"`{TABLE_I_SCENARIO}`", f"{cur} (sim)", f"{order} (sim)", "ratio (sim)",
            f"{cur} (paper)", f"{order} (paper)", "ratio (paper)"]
    n = int(table["n"].min())
    text = (f"{source}: mean ± 95 % t-interval over {_plural(n, 'seed')} (devices) with both rows ok, against "
            f"`torque_ref` (the model torque of the paper's eq. 7) over the evaluation window, and during "
            f"the motion (the samples with a commanded velocity: the paper's 0.16-3.79 s, where it "
            f"scores); the ratio is order-tracking over current-based, of the means. Paper: "
            f"{PAPER_CITATION}, one device, during the motion, quoted beside both rows.\n\n"
            + _markdown(rows, head) + "\n\n")
    return text + "\n".join(f"- {s}" for s in table_one_sentences(table)) + "\n"


def table_one_sentences(table) -> list[str]:
    """Plain-language reading of the replica against the paper, every number from ``table``."""
    cur, order = TABLE_I_METHODS
    out = []
    names = {"max": ("maximum", ""), "rms": ("RMS", ""), "max_motion": ("maximum", " during the motion"),
             "rms_motion": ("RMS", " during the motion")}
    for key, (name, span) in names.items():
        if key not in table.index:
            continue
        r = table.loc[key]
        better = "lower" if r[order] < r[cur] else "higher"
        agree = "as in the paper" if (r[order] < r[cur]) == (r[f"paper_{order}"] < r[f"paper_{cur}"]) \
            else "unlike the paper"
        ratio_lo = r["ratio_pct_seeds"] - r["ratio_pct_half"]
        ratio_hi = r["ratio_pct_seeds"] + r["ratio_pct_half"]
        if np.isfinite(r["ratio_pct_half"]):
            where = "inside" if ratio_lo <= r["paper_ratio_pct"] <= ratio_hi else "outside"
            judged = (f"The paper's ratio is {where} the 95 % interval of the per-seed ratio, "
                      f"{fmt_interval(r['ratio_pct_seeds'], r['ratio_pct_half'])} %.")
        else:
            judged = "One seed: no interval to compare the paper's ratio with."
        out.append(
            f"{name} error{span}: order tracking is {better} than current-based ({r[order]:.3g} vs "
            f"{r[cur]:.3g} Nm, ratio {r['ratio_pct']:.0f} %), {agree} ({r[f'paper_{order}']:g} vs "
            f"{r[f'paper_{cur}']:g} Nm, {r['paper_ratio_pct']:g} %). {judged} "
            f"Absolute errors: simulated current-based is {r[cur] / r[f'paper_{cur}']:.2f} x the paper's, "
            f"order tracking {r[order] / r[f'paper_{order}']:.2f} x.")
    return out
