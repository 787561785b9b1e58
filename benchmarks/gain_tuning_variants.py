"""What ``gain-tuned``'s fit leaves, and the two variants it does not use (docs/methods/gain-tuned.md).

For ``ring-5`` and ``ring-9`` (seeds 0-3): the gauges' order 2 left in the sum on
``paper-quintic`` (the amplitude of order 2 in ``sum / gain - torque_true``, by least squares
over the scored window), with equal weights and with the weights fitted on the calibration
log by ``tuned_weights`` (a) as the method does, (b) with ``gear-aware``'s inertial rows of
the gear's torque beside the harmonics, (c) on the calibration's ticks below 12 rad/s of
motor speed only. Run: ``python benchmarks/gain_tuning_variants.py`` (some 2 minutes).
"""

import rippleb  # noqa: F401 - before numpy: the portable numeric paths (rippleb/numerics.py)

import dataclasses

import numpy as np

from rippleb.dsp import encoder_angle, fit_gain_offset
from rippleb.layouts import GaugeSettings
from rippleb.methods import gain_tuned
from rippleb.methods.gear_aware import gear_rows, smooth
from rippleb.simulator.scenario import load_scenario
from rippleb.simulator import simulate

SLOW_RAD_S = 12.0


def order_2_left(weights, calibration, sim) -> float:
    """Order 2 [Nm] of the weighted sum's error on ``sim``, gain and offset fitted against
    the calibration's true torque (so only the ripple is measured)."""
    gain, offset = fit_gain_offset(calibration.channels @ weights, calibration.torque_true)
    error = (sim.log.channels @ weights) * gain + offset - sim.log.torque_true
    m = sim.eval_mask
    angle = encoder_angle(sim.log.encoder[m], sim.log.spec.counts_per_rev)
    design = np.column_stack([np.ones(m.sum())] + [f(k * angle) for k in range(1, 9) for f in (np.cos, np.sin)])
    coef = np.linalg.lstsq(design, error[m], rcond=None)[0]
    return float(np.hypot(coef[3], coef[4]))


def with_gear_rows(channels, torque, angle, tick_s):
    """The method's weights with the gear's inertial rows fitted beside the harmonics."""
    speed = smooth(np.gradient(angle, tick_s), 5)
    accel = smooth(np.gradient(speed, tick_s), 5)
    gains, harmonics = gain_tuned.harmonic_coefficients(channels, torque, angle, 8,
                                                        extra=gear_rows(angle, speed, accel, (1, 2)))
    return gain_tuned.null_weights(gains, harmonics, 1e-3)


if __name__ == "__main__":
    print("| layout | seed | equal | fitted (the method) | with gear rows | slow ticks only |\n|---|---:|---:|---:|---:|---:|")
    for name in ("ring-5", "ring-9"):
        settings = GaugeSettings(layout=name)
        for seed in range(4):
            calibration = simulate(dataclasses.replace(load_scenario("calibration"), gauges=settings), seed).log
            sim = simulate(dataclasses.replace(load_scenario("paper-quintic"), gauges=settings), seed)
            channels, torque, angle = gain_tuned.tick_means(calibration)
            tick_s = calibration.spec.block_size / calibration.spec.fs
            slow = np.abs(np.gradient(angle, tick_s)) < SLOW_RAD_S
            k = channels.shape[1]
            weights = [np.full(k, 1.0 / k), gain_tuned.tuned_weights(channels, torque, angle, 8, 1e-3),
                       with_gear_rows(channels, torque, angle, tick_s),
                       gain_tuned.tuned_weights(channels[slow], torque[slow], angle[slow], 8, 1e-3)]
            print(f"| {name} | {seed} | " + " | ".join(f"{order_2_left(w, calibration, sim):.3f}" for w in weights)
                  + " |")
