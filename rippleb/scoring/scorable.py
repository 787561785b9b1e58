"""Whether a row of a recorded log can be scored right; rows that cannot are never ``ok``.

Two rules, applied to every row of a recorded log (:func:`rippleb.scoring.row.score_or_invalid`):

* **Scale.** An estimate whose peak exceeds :data:`~rippleb.data.MAX_TORQUE_FACTOR` times the
  joint's rated torque is ``invalid``, with a message, not a number. No harmonic drive carries
  that (its momentary peak limit is 4-7 times rated), so the estimate is not of a torque the
  joint carried; almost always the scored log's columns are in other units than the
  calibration log's (strain in mV against V scales the estimate 1000-fold). The rule reads the
  estimate alone, never a reference, so it holds for a log without one too.
* **Reference.** A log with neither ``torque_ref`` nor ``torque_true`` gives the row status
  :data:`NO_REFERENCE`: the method ran on it to the end and its cost is measured, but its
  accuracy has nothing to be scored against.

Simulated rows are not checked for scale: the simulator's loads stay within the rated range
(:data:`rippleb.simulator.scenario.MAX_LOAD_FACTOR`) and their scores are against the truth.
"""

from __future__ import annotations

import numpy as np

#: Status of a row scored on a log without any reference torque.
NO_REFERENCE = "no-reference"
#: Statuses of rows whose method ran to the end on a log it may be scored on: their cost
#: and truth-free scores are measured, and a recording's report ranks them.
MEASURED = ("ok", NO_REFERENCE)
#: What a row on a log without a reference says.
NO_REFERENCE_MESSAGE = ("the log has no reference torque (no torque_ref or torque_true column): its accuracy "
                        "cannot be scored (the error, delay, bandwidth, stopped and restart columns stay "
                        "empty); scored: the method ran on the whole log, its estimate is within the joint's "
                        "range, its cost (us_per_tick, samples_per_s) and its truth-free scores (ripple_wg_nm, "
                        "rest_std_nm, strain_delay_ms; real torque at the wave-generator orders looks like "
                        "ripple to them) are measured; record a reference torque (a load cell) in a "
                        "torque_ref column to rank accuracy")


def implausible(estimate: np.ndarray, torque_limit: float | None) -> str:
    """Why ``estimate`` cannot be a torque of the joint (its peak beyond ``torque_limit``), or ''.

    ``torque_limit`` None (simulated rows) checks nothing.
    """
    if torque_limit is None or not len(estimate):
        return ""
    peak = float(np.max(np.abs(estimate)))
    if peak <= torque_limit:
        return ""
    return (f"its estimate reaches {peak:.4g} Nm, beyond {torque_limit:g} Nm, the most any joint of this "
            f"rated torque carries: not a torque of this joint, so not scored; are the scored log's "
            f"columns in the units of the calibration log (strain in mV against V)? give each log's units "
            f"in [joint.columns] (docs/your-joint.md), or the joint's rated_torque")
