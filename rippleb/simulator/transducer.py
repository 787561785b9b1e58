"""A torque transducer in series with the joint: a bench's reference of the real torque.

A lab that scores a strain-gauge joint against a reference puts a torque flange between the
drive's output and the load. It reads the torque the shaft carries, the gear's own torque
included, through its own bandwidth and with its own noise. ``rippleb simulate --format lab
--reference transducer`` writes this reading as the log's ``torque_ref``
(:mod:`rippleb.lab_format`); it is derived from the simulator's truth and produced only
here, never streamed to a method in a scored log.

Values, from the data sheet of HBM's T40B torque flange (B3406, nominal torque 100 N m, the
smallest of its ratings above a size-25 drive's rated 51 Nm; accuracy class 0.05):

* bandwidth: its measurement frequency range reaches 6 kHz (-3 dB) (:data:`BANDWIDTH_HZ`).
  The data sheet gives the -3 dB point only; the second-order Butterworth response below it
  is an **estimate** (the order of an amplifier's anti-alias stage). At most 0.4 ``fs``,
  so the filter exists at low sample rates.
* noise: 0.03 % of the nominal torque, 0.03 N m RMS over its band (:data:`NOISE_NM`). An
  **estimate**: the data sheet gives no noise density; 0.03 % is its relative standard
  deviation of repeatability, the scatter of repeated readings of one torque.
* what it reads: the shaft torque of the simulator (``torque_true``). Its rotor's inertia,
  0.001 kg m^2, between the drive's output and the link, changes the torque it reads by
  that inertia times the link's acceleration, under 0.1 % of the arm's: left out
  (**estimate**).
"""

from __future__ import annotations

import numpy as np
from scipy import signal

from rippleb.simulator.conditions import stream

#: -3 dB bandwidth [Hz] of the flange (HBM T40B data sheet: "up to 6 kHz (-3 dB)").
BANDWIDTH_HZ = 6000.0
#: Its filter's order: an **estimate** (the data sheet gives the -3 dB point only).
FILTER_ORDER = 2
#: RMS noise [Nm]: 0.03 % of the 100 N m flange's nominal torque (**estimate**, see above).
NOISE_NM = 0.03
#: The filter's cutoff never exceeds this fraction of the sample rate.
MAX_CUTOFF_FS = 0.4


def reading(torque_true: np.ndarray, fs: float, seed: int, scenario: str) -> np.ndarray:
    """The flange's reading [Nm] of the shaft torque ``torque_true`` sampled at ``fs``.

    Its noise comes from a generator of its own for ``(seed, scenario)``: the same log
    reads the same every time, and the sensors' noise is that of the log without it.
    """
    torque = np.asarray(torque_true, float)
    cutoff = min(BANDWIDTH_HZ, MAX_CUTOFF_FS * fs)
    b, a = signal.butter(FILTER_ORDER, cutoff, fs=fs)
    filtered = signal.lfilter(b, a, torque, zi=signal.lfilter_zi(b, a) * torque[0])[0]
    return filtered + stream(seed, scenario, "transducer").normal(0.0, NOISE_NM, len(torque))


def lab_log(sim, kind: str):
    """The log of the simulation ``sim`` as a lab with a reference of ``kind`` records it
    (:data:`rippleb.joint_file.REFERENCE_KINDS`): its ``torque_ref`` is the flange's
    :func:`reading` of the true torque, or eq. (7)'s model torque (the simulator's own
    ``torque_ref``), and ``meta["reference_kind"]`` says which. ``torque_true`` stays for
    the one who scores it; :func:`rippleb.lab_format.lab_columns` leaves it out of a file."""
    import dataclasses

    log = sim.log
    reference = log.torque_ref if kind == "model" else reading(log.torque_true, log.spec.fs,
                                                               int(log.meta["seed"]), sim.scenario.name)
    return dataclasses.replace(log, torque_ref=reference, meta={**log.meta, "reference_kind": kind})
