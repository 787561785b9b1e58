"""The joint simulator, one module per physical part.

========================  ==========================================================
module                    what it holds
========================  ==========================================================
``simulation``            :func:`simulate` and :class:`Simulation`: puts the parts together
``device``                :class:`Device`, the hidden truth of one joint (gauge errors,
                          wave-generator ripple, friction, offsets)
``joint``                 the drive's torsional compliance, the arm load it carries, and
                          the compiled integrator of the two-mass joint
``controller``            the position controller (PD + eq. (7) feedforward) and its design
``robot``                 the arm load through Pinocchio, and the nominal model of eq. (7)
``ripple``                output-locked ripple, ripple temperature scale, strain hysteresis
``sensors``               strain bridge, current sense, encoder counter, ADCs, sensor faults
``conditions``            deployment conditions and the encoder's index pulse
``gauge``                 beyond the methods' models: the flexspline mode, non-affine and
                          flank-dependent ripple, span drift (:mod:`rippleb.simulator.mismatch`)
``daq``                   beyond the methods' models: anti-alias filter, PWM pickup
``encoder``               beyond the methods' models: edge errors, eccentricity, missed counts
========================  ==========================================================

Every default is listed with its source in ``docs/physics.md``.

The names below are imported on first use (PEP 562): the runner and the CLI need the
deployment conditions (``rippleb.simulator.conditions``) without paying for the joint's
compiled kernels and Pinocchio, which only simulating needs.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from rippleb._lazy import lazy_exports

_EXPORTS = {
    "Device": "rippleb.simulator.device",
    "twist": "rippleb.simulator.joint",
    "quantise": "rippleb.simulator.sensors",
    "Simulation": "rippleb.simulator.simulation",
    "simulate": "rippleb.simulator.simulation",
}

if TYPE_CHECKING:  # what static tools see: the same names, imported eagerly
    from rippleb.simulator.device import Device
    from rippleb.simulator.joint import twist
    from rippleb.simulator.sensors import quantise
    from rippleb.simulator.simulation import Simulation, simulate


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)


__all__ = ["Device", "Simulation", "quantise", "simulate", "twist"]
