"""The sweepable parameters: scenario-file keys, each with its type and valid range.

Apart from :mod:`rippleb.engine.sweep`, which runs a grid of them: the result rows have a
column per swept parameter, so reading and writing rows (:mod:`rippleb.engine.results`)
needs these names without the sweep itself.
"""

from __future__ import annotations

from dataclasses import dataclass

from rippleb.errors import InputError
from rippleb.layouts import LAYOUT_NAMES, MAX_MISALIGNMENT
from rippleb.simulator.mismatch import KNOBS as _KNOBS


@dataclass(frozen=True)
class Param:
    """A parameter that can be swept: where it lives, its type, its valid range and why.

    Attributes
    ----------
    name
        The dotted key in a scenario file, also the result column.
    kind
        ``int`` or ``float``.
    low, high
        Valid range, inclusive.
    doc
        What it changes, one line (``rippleb sweep --help`` lists it).
    device
        True for the joint's hardware (encoder, DAQ, gear): the calibration session is
        run on the same hardware, so it is swept too. False for a property of the scored
        session only (its temperature): the calibration keeps its own.
    choices
        Names an ``int`` parameter also takes, each meaning its position (a gauge layout):
        the rows hold the number, :meth:`name_of` turns it back.
    """

    name: str
    kind: type
    low: float
    high: float
    doc: str
    device: bool = True  # a property of the device: its calibration session has it too
    choices: tuple[str, ...] = ()

    def parse(self, text: str):
        """One value from the command line, range-checked; raises one clear line."""
        if text in self.choices:
            return self.choices.index(text)
        try:
            value = self.kind(text) if self.kind is float else int(text, 10)
        except ValueError:
            what = f"one of {', '.join(self.choices)}" if self.choices else \
                ("an integer" if self.kind is int else "a number")
            raise InputError(f"--param {self.name}: {text!r} is not {what}") from None
        if not self.low <= value <= self.high:
            raise InputError(f"--param {self.name}: {value:g} is outside the valid range "
                             f"[{self.low:g}, {self.high:g}]")
        return value

    def name_of(self, value) -> str:
        """A value as the report writes it: the choice's name, else the number."""
        if self.choices and float(value).is_integer() and 0 <= int(value) < len(self.choices):
            return self.choices[int(value)]
        return f"{value:g}"


#: Every sweepable parameter (docs/sweeps.md lists them with the reasons for their ranges).
PARAMS = {p.name: p for p in (
    Param("joint.counts_per_rev", int, 64, 2**20,
          "encoder positions per motor revolution (paper: 2500)"),
    Param("joint.fs", float, 2_000.0, 100_000.0,
          "DAQ sample rate of strain and current [Hz] (default 20 kHz)"),
    Param("joint.control_rate", float, 100.0, 10_000.0,
          "control tick rate [Hz] (default 1 kHz); must not exceed joint.fs"),
    Param("joint.gear_ratio", float, 30.0, 160.0,
          "harmonic-drive reduction (size-25 catalogue ratios 30-160; default 100)"),
    Param("temperature_c", float, -10.0, 80.0,
          "lubricant temperature of the scored session [degC] (default 40)", device=False),
    Param("gear.transmission_error", float, 0.0, 5.8e-4,
          "the drive's transmission-error class [rad peak to peak] (default 2.9e-4, the CSF "
          "catalogue's standard class; 0: an ideal gear)"),
    Param("gear.order2_share", float, 0.0, 1.0,
          "share of the transmission-error class taken by its twice-per-turn component (default "
          "0.25, held to the paper's Fig. 2; up to 0.5 the worst-case sum stays inside the class)"),
    Param("ripple.drift", float, 0.0, 5.0,
          "drift of ripple and bridge zero since calibration, x the documented estimate "
          "(default 1); acts under --conditions aged only", device=False),
    Param("gauges.layout", int, 0, len(LAYOUT_NAMES) - 1,
          f"strain-gauge layout on the flexspline, by name ({', '.join(LAYOUT_NAMES)}; default paper); "
          f"the rows hold its position in that list", choices=LAYOUT_NAMES),
    Param("gauges.misalignment", float, 0.0, MAX_MISALIGNMENT,
          "the gauges' placement, orientation and gain errors, x the documented sizes (default 1; 0: perfect)"),
)}

#: The physics beyond the methods' models (:mod:`rippleb.simulator.mismatch`, docs/physics.md "Beyond
#: the methods' models"), one parameter per knob: properties of the joint, so its calibration
#: session has them too. A value set by a sweep acts under every condition; under
#: ``realistic`` the knobs not swept keep their documented magnitudes. Ranges: from off to a
#: few times the ``realistic`` magnitude (docs/sweeps.md gives the reason for each).
UNMODELLED_RANGES = {
    "mismatch.gauge_mode_hz": (0.0, 5000.0), "mismatch.load_saturation": (0.0, 5.0),
    "mismatch.flank_asymmetry": (0.0, 0.5), "mismatch.extra_orders": (0.0, 3.0),
    "mismatch.load_history": (0.0, 10.0), "thermal.gain_coeff": (-1.0e-3, 1.0e-3),
    "thermal.warmup_rate": (0.0, 10.0), "daq.adc_bits": (8, 24), "daq.antialias_hz": (0.0, 20_000.0),
    "daq.pwm_mv": (0.0, 100.0), "daq.pwm_hz": (4000.0, 100_000.0), "encoder.edge_error": (0.0, 30.0),
    "encoder.eccentricity": (0.0, 5.0), "encoder.missed": (0.0, 1.0e-3),
    "controller.bandwidth_factor": (0.5, 3.0), "gear.compliance_variation": (0.0, 0.2),
    "gear.order4_error": (0.0, 1.0), "gear.load_error": (0.0, 2.0), "gear.loss_factor": (0.0, 0.3),
}
PARAMS.update({k.name: Param(k.name, k.kind, *UNMODELLED_RANGES[k.name], k.doc) for k in _KNOBS})
