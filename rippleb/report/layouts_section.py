"""The report's "Gauge layouts and hardware compensation": how many gauges, where, and which
software on top, from the rows of a sweep over ``gauges.layout`` (and ``gauges.misalignment``).

For each condition, each layout (at each swept misalignment) and each method, per device the
mean over the scenarios every combination finished of ``rms_error_nm`` and of the residual
ripple ``ripple_wg_nm``; then their mean over devices with a 95 % t interval, and the paired
per-device difference from the same method on the paper's layout (:mod:`rippleb.report.paired`):
the devices are shared, so the difference is the layout's and not the device's. ``raw`` is a
layout alone, ``gain-tuned`` (``then=raw``) its tuned hardware, ``X`` and ``gain-tuned[then=X]``
the software method ``X`` on the plain and on the tuned sum.

The cost of a combination is what the hardware needs (gauges, amplifier channels:
:mod:`rippleb.layouts`) and what its method costs per control tick (``us_per_tick_p50``, the
median over its rows: timing on a shared machine is noisy, so read it as an order). For
each target error of :data:`TARGETS_NM`, the report names the cheapest combination whose
whole 95 % interval lies below it: fewest gauges, then fewest channels, then the fastest.
"""

from __future__ import annotations

import numpy as np

from rippleb.layouts import DEFAULT_LAYOUT, layout
from rippleb.report.markdown import markdown
from rippleb.report.paired import paired_test
from rippleb.report.stats import condition_order, fmt_interval, method_order, ok_rows, t_interval

LAYOUT_COLUMN = "gauges.layout"
MISALIGNMENT_COLUMN = "gauges.misalignment"
#: Errors a torque controller might be asked to reach [Nm RMS]: round values around what the
#: paper's layout reaches with and without software (docs/report.md). **Estimate**.
TARGETS_NM = (1.0, 0.75, 0.5, 0.35)


def layout_name(value) -> str:
    """The layout a row's ``gauges.layout`` cell names."""
    from rippleb.engine.params import PARAMS

    return PARAMS[LAYOUT_COLUMN].name_of(value)


def per_device(frame, column: str):
    """Per (condition, layout, misalignment, method, seed): the mean of ``column`` over the
    scenarios every combination of the condition finished ok."""
    ok = ok_rows(frame).copy()
    ok["layout"] = ok[LAYOUT_COLUMN].map(layout_name)
    ok["misalignment"] = ok[MISALIGNMENT_COLUMN] if MISALIGNMENT_COLUMN in ok else 1.0
    keys = ["condition", "layout", "misalignment", "method"]
    out = []
    for condition, rows in ok.groupby("condition", sort=False):
        combos = rows.groupby(keys)["scenario"].agg(set)
        common = set.intersection(*combos) if len(combos) else set()
        kept = rows[rows["scenario"].isin(common)]
        out.append(kept.groupby(keys + ["seed"])[column].mean().rename("value").reset_index())
    import pandas as pd

    return pd.concat(out, ignore_index=True) if out else pd.DataFrame(columns=keys + ["seed", "value"])


def combination_table(frame, condition: str):
    """The rows of one condition's table: one dict per (layout, misalignment, method)."""
    errors = per_device(frame, "rms_error_nm")
    ripple = per_device(frame, "ripple_wg_nm") if "ripple_wg_nm" in frame else None
    errors = errors[errors["condition"] == condition]
    timing = ok_rows(frame)
    timing = timing.assign(layout=timing[LAYOUT_COLUMN].map(layout_name))
    rows = []
    for (name, misalignment, method), group in errors.groupby(["layout", "misalignment", "method"]):
        series = group.set_index("seed")["value"]
        mean, half, n = t_interval(series)
        reference = errors[(errors["layout"] == DEFAULT_LAYOUT) & (errors["misalignment"] == misalignment)
                           & (errors["method"] == method)].set_index("seed")["value"]
        lead = paired_test(series, reference) if name != DEFAULT_LAYOUT and len(reference) else None
        ripple_mean = np.nan
        if ripple is not None:
            mine = ripple[(ripple["condition"] == condition) & (ripple["layout"] == name)
                          & (ripple["misalignment"] == misalignment) & (ripple["method"] == method)]
            ripple_mean = float(mine["value"].mean()) if len(mine) else np.nan
        lay = layout(name)
        ticks = timing.loc[(timing["method"] == method) & (timing["condition"] == condition)
                           & (timing["layout"] == name), "us_per_tick_p50"]
        rows.append(dict(layout=name, misalignment=float(misalignment), method=method, mean=mean, half=half, n=n,
                         lead=lead, ripple=ripple_mean, gauges=lay.gauges, channels=lay.amplifiers,
                         us=float(np.nanmedian(ticks)) if len(ticks) else np.nan))
    order = {m: i for i, m in enumerate(method_order([r["method"] for r in rows]))}
    return sorted(rows, key=lambda r: (r["gauges"], r["channels"], r["layout"], r["misalignment"],
                                       order[r["method"]]))


def cheapest(rows, target: float):
    """The cheapest combination whose 95 % interval lies wholly below ``target`` [Nm]."""
    reached = [r for r in rows if np.isfinite(r["half"]) and r["mean"] + r["half"] < target]
    return min(reached, key=lambda r: (r["gauges"], r["channels"], r["us"]), default=None)


def layouts_markdown(frame) -> list[str]:
    """The section's lines, or none when the rows hold no ``gauges.layout`` column."""
    if LAYOUT_COLUMN not in frame or not frame[LAYOUT_COLUMN].notna().any():
        return []
    swept = MISALIGNMENT_COLUMN in frame
    parts = ["## Gauge layouts and hardware compensation", "",
             "How many gauges, where, and which software on top (docs/physics.md, \"Gauges on the "
             "flexspline\"): per combination, the mean over the scenarios of `rms_error_nm` and of the "
             "residual ripple `ripple_wg_nm` per device, then mean ± 95 % interval over devices; "
             f"*vs {DEFAULT_LAYOUT}*: the paired per-device difference from the same method on the paper's "
             "layout (positive: this layout lower). `raw` is the layout alone, `gain-tuned` its gains "
             "tuned on the calibration log, `gain-tuned[then=X]` the method X on the tuned sum. "
             "Cost: gauges, amplifier channels, and the method's median µs per control tick (timing on "
             "a shared machine: read it as an order).", ""]
    for condition in condition_order(frame["condition"].unique()):
        rows = combination_table(frame, condition)
        if not rows:
            continue
        parts += [f"### {condition}", ""]
        headers = ["layout"] + (["misalignment"] if swept else []) + \
            ["method", "gauges", "channels", "rms_error_nm", f"vs {DEFAULT_LAYOUT}", "ripple_wg_nm", "µs/tick"]
        table = []
        for r in rows:
            lead = "" if r["lead"] is None else \
                f"{fmt_interval(r['lead'].mean, r['lead'].half)} ({r['lead'].wins}/{r['lead'].n})"
            table.append([r["layout"]] + ([f"{r['misalignment']:g}"] if swept else [])
                         + [r["method"], r["gauges"], r["channels"], fmt_interval(r["mean"], r["half"]), lead,
                            f"{r['ripple']:.3f}", f"{r['us']:.1f}"])
        parts += [markdown(table, headers), ""]
        for target in TARGETS_NM:
            best = cheapest(rows, target)
            where = f" at misalignment {best['misalignment']:g}" if best is not None and swept else ""
            parts.append(f"- below {target:g} Nm: " + (
                f"`{best['layout']}` with `{best['method']}`{where} ({best['gauges']} gauges, "
                f"{best['channels']} channel(s), {fmt_interval(best['mean'], best['half'])} Nm)"
                if best is not None else "no combination's 95 % interval lies below it"))
        parts.append("")
    return parts
