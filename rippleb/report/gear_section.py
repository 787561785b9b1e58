"""The report's section on the gear's real torque: what each method did with it.

Every harmonic drive's transmission error puts real torque at the ripple's own orders
(docs/physics.md, "Transmission error"); this section shows, per condition, the share of it
each method took out of the strain it read (``gear_removed_fraction``) and its error against
the joint without it (``rms_error_without_gear_nm``). :mod:`rippleb.report.writer` places it
after the headline, beside :mod:`rippleb.report.layouts_section`.
"""

from __future__ import annotations

from rippleb.report.tables import condition_headline, condition_summary_markdown


def gear_markdown(frame) -> list[str]:
    """What each method did with the gear's real torque (docs/metrics.md, "What a method
    erased"): the share it took out of the strain and its error against the joint without
    it, per condition."""
    if "gear_removed_fraction" not in frame or not frame["gear_removed_fraction"].notna().any():
        return []
    return ["## What each method did with the gear's real torque", "",
            "Every harmonic drive's transmission error puts real torque at the ripple's own orders "
            "(docs/physics.md, \"Transmission error\"). `gear_removed_fraction`: the share of it a "
            "method took out of the strain it read (0: passed on as the strain carries it, `raw` "
            "exactly; 1: removed as much as the gear puts in). The strain itself lacks part of it "
            "(its hysteresis absorbs small oscillations), which no method is charged for; ripple a "
            "method removes at orders 1 and 2 moves it on single devices, so read the means. A "
            "torque controller needs the real torque and ranks by `rms_error_nm` above; an "
            "application that wants the gear's torque gone ranks by `rms_error_without_gear_nm`.", "",
            "### `gear_removed_fraction` (mean over the scenarios, 95 % interval)", "",
            condition_summary_markdown(frame, "gear_removed_fraction"), "",
            "### `rms_error_without_gear_nm` (mean over the scenarios, 95 % interval)", "",
            condition_summary_markdown(frame, "rms_error_without_gear_nm"), ""] + \
        [f"- {s}" for s in condition_headline(frame, "rms_error_without_gear_nm")] + [""]
