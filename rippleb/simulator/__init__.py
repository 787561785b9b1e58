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
========================  ==========================================================

Every default is listed with its source in ``docs/physics.md``.
"""

from rippleb.simulator.device import Device
from rippleb.simulator.joint import twist
from rippleb.simulator.sensors import quantise
from rippleb.simulator.simulation import Simulation, simulate

__all__ = ["Device", "Simulation", "quantise", "simulate", "twist"]
