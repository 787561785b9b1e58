"""Per method, in plain words: where it wins, where it breaks, and why.

The *where* is computed from the rows (the method x condition summary of
:func:`rippleb.report.tables.condition_summary`); the *why* is each built-in method's model, in
words that hold whatever the numbers: what it assumes of the ripple, and so what physics
it cannot follow. No number is typed here. A plugin gets the computed part only.
"""

from __future__ import annotations

from rippleb.printable import markdown_code as code
from rippleb.report.stats import fmt_interval, method_order
from rippleb.report.tables import condition_summary

#: What each built-in method assumes, and what therefore breaks it (docs/methods/*.md).
MECHANISMS = {
    "raw": "it removes nothing: its error is the whole ripple plus the gain and offset fitted on "
           "the calibration log, so it is the yardstick every other method must beat",
    "lowpass": "a fixed low-pass removes the ripple only above its cut-off; at low speed the ripple's "
               "orders fall inside the pass band, and everywhere it adds delay",
    "current-based": "it never reads the strain, so the ripple and every gauge effect pass it by; its "
                     "error is the friction and inertia it cannot identify exactly and the current's "
                     "noise, and a condition that changes only the gauge does not reach it",
    "order-tracking": "it notches fixed orders (2, 4, 8) of the encoder angle whatever their amplitude, "
                      "so it follows drift and load, but not orders it does not notch (1, 6) nor "
                      "components locked to the output; its dead zone holds the estimate at stops",
    "order-tracking-no-deadzone": "the paper's method without the dead zone: at a stop the re-sampled "
                                  "signal stops and the notches ring, so it breaks where the joint rests",
    "order-tracking-no-backprop": "the paper's method without back propagation: the notches' phase lag "
                                  "stays in the estimate",
    "switched-notch": "time-domain notches tuned to the measured speed: the ripple must sit at the "
                      "band's frequency, so speed changes, stops and reversals leave ripple through",
    "kalman-ripple": "fixed harmonics of the motor angle as states, with a load map fitted on the "
                     "calibration log: a ripple of another form (other orders, a non-affine load "
                     "law, another flank) is left to its torque state; its noise levels come from a "
                     "likelihood search that can tip between two devices' logs",
    "angle-adaptive": "a load-dependent map indexed by the encoder angle, learned online: it follows "
                      "drift and re-assembly as far as the map can express them; a ripple that no "
                      "angle-indexed map affine in the load can express (speed-dependent gauge "
                      "dynamics, a saturating load law, a flank change) is what it cannot learn",
    "angle-adaptive-frozen": "the calibration's map, never adapted: exact while the joint stays as "
                             "calibrated, wrong by whatever changed since (aging, re-assembly)",
    "gear-aware": "angle-adaptive-frozen's map fitted beside an inertial model of the gear's "
                  "transmission-error torque: on the built-in calibration, which turns at many "
                  "speeds, that changes the map little, so it keeps no more of the gear's torque "
                  "than the frozen map and is wrong by whatever changed since calibration",
    "gear-keeping": "angle-adaptive's map, fitted and learned beside an encoder model of the gear's "
                    "dynamic torque (speed squared and acceleration, zero at rest) whose prediction "
                    "its learning takes out and its estimate keeps, and learned only up to the "
                    "calibration's top speed: it follows drift where it learns, holds its map where "
                    "the joint turns faster than the calibration did, so a ripple changed since "
                    "calibration (re-assembly) is re-learned only at lower speeds, and a gear torque "
                    "its model misses (a resonance) still reaches its learning",
    "spatial-filter": "band-passes at orders 2, 4, 8 stepped in angle: they need no map, so drift, "
                      "re-assembly and power cycles pass them by, but they fade out at rest and at "
                      "low speed (the ripple stays there) and take the part of every torque change "
                      "that falls near the ripple orders in angle",
    "fourier-lms": "a map of fixed harmonics of the encoder angle, warm-started from calibration and "
                   "adapted by LMS per radian turned: it follows drift and load as fast as its step "
                   "allows and holds at rest, but over a short move the torque correlates with the "
                   "harmonics and leaks into the weights, which then hold it at rest; it runs in the "
                   "wrong frame until the first index pulse after a power cycle, and cannot follow "
                   "orders it does not list or components locked to the output",
    "gain-tuned": "per-channel gains tuned on the calibration log to null what the gauges' placement "
                  "leaves at the wave-generator orders: with one bridge there is nothing to tune and it is "
                  "its inner method (raw); with several channels it cannot tell that ripple from real "
                  "torque the calibration's reference misses at the same orders, and it holds the "
                  "calibration's gains through whatever changes the gauges since (re-assembly)",
    "periodic-dob": "a comb over one turn of the encoder angle, any ripple shape, learned on the "
                    "strain minus a low-passed torque: it holds at rest and needs no order list, but "
                    "learns slowly (the load dependence and a changed ripple take many turns), "
                    "is resolved to its angle bins and runs in the wrong frame until the first "
                    "index pulse after a power cycle",
}


def method_verdicts(frame, column: str = "rms_error_nm", reference: str = "same-session",
                    mismatch: str = "realistic") -> list[str]:
    """One bullet per method: its rank and best and worst condition from the rows, what the
    ``mismatch`` condition costs it against ``reference``, and its mechanism."""
    table = condition_summary(frame, column)
    if table.empty:
        return []
    table = table.dropna(subset=["mean"])
    table = table.assign(rank=table.groupby("condition")["mean"].rank(method="min").astype(int))
    n_methods = table.groupby("condition")["method"].nunique()
    out = []
    for method in method_order(table["method"].unique()):
        rows = table[table["method"] == method].set_index("condition")
        best, worst = rows["mean"].idxmin(), rows["mean"].idxmax()
        wins = [c for c in rows.index if rows.loc[c, "rank"] == 1]
        text = f"{code(method)}: " + (f"lowest mean under {', '.join(code(c) for c in wins)}; " if wins else "")
        if len(rows) == 1:   # one condition: where it ranks there
            text += (f"rank {rows.loc[best, 'rank']} of {n_methods[best]} under {code(best)} "
                     f"({fmt_interval(rows.loc[best, 'mean'], rows.loc[best, 'half'])})")
        else:
            text += (f"best under {code(best)} ({fmt_interval(rows.loc[best, 'mean'], rows.loc[best, 'half'])}, "
                     f"rank {rows.loc[best, 'rank']} of {n_methods[best]}), worst under {code(worst)} "
                     f"({fmt_interval(rows.loc[worst, 'mean'], rows.loc[worst, 'half'])}, rank "
                     f"{rows.loc[worst, 'rank']} of {n_methods[worst]})")
        if reference in rows.index and mismatch in rows.index:
            ref, mis = rows.loc[reference, "mean"], rows.loc[mismatch, "mean"]
            text += (f"; the physics no method models (`{mismatch}` against `{reference}`) "
                     f"changes its error by {mis - ref:+.3g} Nm ({(mis - ref) / ref:+.0%})")
        why = MECHANISMS.get(method)
        out.append(text + (f". Why: {why}." if why else "."))
    return out
