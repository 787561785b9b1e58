"""Choose the ``lowpass`` cutoff on the calibration scenario only (never on a scored one).

For each cutoff, fit and run ``lowpass`` on ``calibration`` logs of seeds 0-2 and print
the RMS error against ``torque_true``. Run: ``python benchmarks/lowpass_cutoff.py``.
"""

import rippleb  # noqa: F401 - before numpy: the portable numeric paths (rippleb/numerics.py)

import numpy as np

from rippleb.methods.lowpass import Lowpass
from rippleb.scoring.metrics import Truth, score
from rippleb.simulator import simulate
from rippleb.harness import run_method

CUTOFFS_HZ = (2, 5, 10, 20, 30, 50, 100, 200)

if __name__ == "__main__":
    sims = [simulate("calibration", seed) for seed in range(3)]
    print("| cutoff [Hz] | rms_error_nm | delay_ms |\n|---:|---:|---:|")
    for cutoff in CUTOFFS_HZ:
        rows = [score(run_method(Lowpass(cutoff_hz=cutoff), s.log, s.log)[0], Truth.from_simulation(s))
                for s in sims]
        print(f"| {cutoff} | {np.mean([r['rms_error_nm'] for r in rows]):.3f} "
              f"| {np.mean([r['delay_ms'] for r in rows]):.1f} |")
