"""Physics beyond the methods' models: the scenario tables that switch it on, and the
``realistic`` condition's magnitudes.

Every method of the benchmark models the strain as the torque plus a ripple that is a
fixed function of the motor angle and (affinely) of the load. A real flexspline gauge is
not that: its structure responds dynamically, its ripple bends with load and changes
with the tooth flank that carries it, its span drifts with temperature, its DAQ quantises,
filters and picks up the motor drive's switching, and the encoder the methods index by
has its own errors. Each of those is one *knob* here: a documented parameter with an
"off" value (today's physics, bit for bit) and a magnitude under the ``realistic``
condition, with its source or the reason for the estimate (``docs/physics.md``, "Beyond
the methods' models").

A scenario sets knobs in six tables (``[mismatch]``, ``[thermal]``, ``[daq]``,
``[encoder]``, ``[controller]``, ``[gear]``); a knob it sets acts under every condition, one it leaves
unset is off, except under ``realistic``, where it takes its documented magnitude. The
physics lives in :mod:`rippleb.simulator.gauge`, :mod:`rippleb.simulator.daq`,
:mod:`rippleb.simulator.encoder`, :mod:`rippleb.simulator.controller` and
:mod:`rippleb.simulator.transmission`.

Examples
--------
>>> from rippleb.simulator.mismatch import Unmodelled
>>> Unmodelled().resolve(realistic=False).active
False
>>> Unmodelled().resolve(realistic=True).antialias_hz
2500.0
"""

from __future__ import annotations

from dataclasses import dataclass

#: The condition under which every unset knob takes its documented magnitude.
REALISTIC = "realistic"


@dataclass(frozen=True)
class Knob:
    """One switchable effect: where a scenario sets it, its range and its two values.

    Attributes
    ----------
    table, key
        ``[table] key = value`` in a scenario file; ``table.key`` is the sweep name.
    field
        Attribute of :class:`Unmodelled`.
    kind
        ``int`` or ``float``.
    low, high
        Valid range, inclusive (a scenario outside it is refused).
    off
        The value that reproduces the physics without this effect, bit for bit.
    realistic
        The magnitude under the ``realistic`` condition (docs/physics.md gives the source).
    doc
        One line: what it is, with its unit.
    """

    table: str
    key: str
    field: str
    kind: type
    low: float
    high: float
    off: float
    realistic: float
    doc: str

    @property
    def name(self) -> str:
        return f"{self.table}.{self.key}"


#: Every knob. The magnitudes are argued in docs/physics.md, "Beyond the methods' models".
KNOBS = (
    Knob("mismatch", "gauge_mode_hz", "gauge_mode_hz", float, 0.0, 20_000.0, 0.0, 1500.0,
         "flexspline/circular-spline mode that filters the wave-generator ripple [Hz] (0: rigid)"),
    Knob("mismatch", "load_saturation", "load_saturation", float, 0.0, 10.0, 0.0, 2.3,
         "curvature of the ripple's load growth, rated torque / knee torque (0: affine)"),
    Knob("mismatch", "flank_asymmetry", "flank_asymmetry", float, 0.0, 1.0, 0.0, 0.2,
         "ripple change when the load changes tooth flank: log-amplitude and phase sigma (0: none)"),
    Knob("mismatch", "extra_orders", "extra_orders", float, 0.0, 5.0, 0.0, 1.0,
         "ripple at order 3 and at the wave-generator bearing's non-integer ball-pass order, "
         "x the device's order-8 amplitude (0: none)"),
    Knob("mismatch", "load_history", "load_history_nm", float, 0.0, 20.0, 0.0, 2.55,
         "play width [Nm] of the load the ripple follows: loading and unloading differ (0: |tau| itself)"),
    Knob("thermal", "gain_coeff", "gain_temp_coeff", float, -0.005, 0.005, 0.0, 3.0e-4,
         "bridge span change per kelvin from 25 degC [1/K] (0: none)"),
    Knob("thermal", "warmup_rate", "warmup_k_per_min", float, 0.0, 20.0, 0.0, 1.0,
         "gauge warm-up during a log [K/min]: moves zero and span within the log (0: none)"),
    Knob("daq", "adc_bits", "adc_bits", int, 8, 24, 16, 16,
         "strain ADC word length [bit] over +-10 V (today: 16)"),
    Knob("daq", "antialias_hz", "antialias_hz", float, 0.0, 100_000.0, 0.0, 2500.0,
         "cut-off of the bridge amplifier's 2-pole Butterworth anti-alias filter [Hz] (0: none)"),
    Knob("daq", "pwm_mv", "pwm_mv", float, 0.0, 1000.0, 0.0, 10.0,
         "motor-drive PWM pickup on the bridge output, fundamental amplitude [mV] (0: none)"),
    Knob("daq", "pwm_hz", "pwm_hz", float, 1000.0, 200_000.0, 20_000.0, 20_000.0,
         "motor-drive PWM switching frequency [Hz] (acts with daq.pwm_mv)"),
    Knob("encoder", "edge_error", "edge_error_deg", float, 0.0, 40.0, 0.0, 15.0,
         "quadrature edge placement error, sigma of the A/B phase error [electrical deg] (0: none)"),
    Knob("encoder", "eccentricity", "eccentricity_counts", float, 0.0, 20.0, 0.0, 0.5,
         "code-disc eccentricity: once-per-revolution angle error amplitude [counts] (0: none)"),
    Knob("encoder", "missed", "missed", float, 0.0, 0.01, 0.0, 1.0e-5,
         "probability that the DAQ's counter loses one encoder edge, both sessions (0: none)"),
    # Not raised under `realistic` (1 there too): a stiffer loop changes the torque the joint
    # carries, not what its sensor reads, so realistic rows would not score the same joint as
    # same-session rows; the speed non-uniformity it stands for is already in today's loop.
    Knob("controller", "bandwidth_factor", "bandwidth_factor", float, 0.25, 4.0, 1.0, 1.0,
         "position-loop bandwidth in multiples of the documented design (1: today; a sweep knob)"),
    # The real torque locked to the wave-generator angle beyond the kinematic error (the
    # [gear] table also holds transmission_error and order2_share, which act in every
    # condition): rippleb/simulator/transmission.py, docs/physics.md "Transmission error".
    Knob("gear", "compliance_variation", "compliance_variation", float, 0.0, 0.5, 0.0, 0.02,
         "relative variation of the flexspline's compliance at twice the wave-generator angle (0: none)"),
    Knob("gear", "order4_error", "order4_error", float, 0.0, 2.0, 0.0, 0.25,
         "transmission error at order 4 of the wave-generator angle, x the device's order-2 amplitude (0: none)"),
    Knob("gear", "load_error", "load_error", float, 0.0, 5.0, 0.0, 0.5,
         "growth of the order-2 transmission error at rated torque, relative (0: none)"),
    Knob("gear", "loss_factor", "loss_factor", float, 0.0, 1.0, 0.0, 0.1,
         "the drive's hysteresis loss as structural damping: loss factor at the joint's own mode (0: none)"),
)
KNOB_BY_NAME = {k.name: k for k in KNOBS}
#: ``{table: {key: accepted types}}`` for the scenario parser.
TABLES: dict[str, dict[str, tuple]] = {}
for _k in KNOBS:
    TABLES.setdefault(_k.table, {})[_k.key] = (int,) if _k.kind is int else (float, int)


@dataclass(frozen=True)
class Unmodelled:
    """The knobs of one scenario (None: not set) or, resolved, of one session (all set).

    Attributes are named by :data:`KNOBS` (``gauge_mode_hz``, ``load_saturation``, ...);
    see each knob's ``doc``.
    """

    gauge_mode_hz: float | None = None
    load_saturation: float | None = None
    flank_asymmetry: float | None = None
    extra_orders: float | None = None
    load_history_nm: float | None = None
    gain_temp_coeff: float | None = None
    warmup_k_per_min: float | None = None
    adc_bits: int | None = None
    antialias_hz: float | None = None
    pwm_mv: float | None = None
    pwm_hz: float | None = None
    edge_error_deg: float | None = None
    eccentricity_counts: float | None = None
    missed: float | None = None
    bandwidth_factor: float | None = None
    compliance_variation: float | None = None
    order4_error: float | None = None
    load_error: float | None = None
    loss_factor: float | None = None

    def resolve(self, realistic: bool) -> "Unmodelled":
        """Every knob set: the scenario's value, else the ``realistic`` magnitude under
        that condition, else off."""
        values = {}
        for knob in KNOBS:
            value = getattr(self, knob.field)
            if value is None:
                value = knob.realistic if realistic else knob.off
            values[knob.field] = knob.kind(value)
        return Unmodelled(**values)

    @property
    def active(self) -> bool:
        """True if a resolved set differs from today's physics anywhere."""
        return any(getattr(self, k.field) != k.off for k in KNOBS if k.name != "daq.pwm_hz")

    @property
    def ripple_active(self) -> bool:
        """The wave-generator ripple departs from the device's affine Fourier map."""
        return bool(self.gauge_mode_hz or self.load_saturation or self.flank_asymmetry
                    or self.extra_orders or self.load_history_nm)

    @property
    def encoder_active(self) -> bool:
        """The encoder's edges are not where an ideal disc puts them."""
        return bool(self.edge_error_deg or self.eccentricity_counts)


def parse_tables(top: dict, fail, spec) -> Unmodelled:
    """The knobs set in the tables of a parsed scenario ``top`` (already type-checked).

    ``fail(key, what)`` raises the parser's one-line error; ``spec`` is the scenario's
    :class:`~rippleb.data.JointSpec` (a mode or a filter must be representable at its
    sample rate).
    """
    values = {}
    for table in TABLES:
        for key, value in top.get(table, {}).items():
            knob = KNOB_BY_NAME.get(f"{table}.{key}")
            if knob is None:   # a key of the table that is not a knob ([gear] transmission_error)
                continue
            if not knob.low <= value <= knob.high:
                fail(knob.name, f"must be within [{knob.low:g}, {knob.high:g}] ({knob.doc}), got {value:g}")
            values[knob.field] = knob.kind(value)
    mode = values.get("gauge_mode_hz", 0.0)
    if mode and mode < 50.0:
        fail("mismatch.gauge_mode_hz", f"a structural mode below 50 Hz is the joint's own "
             f"resonance, not the gauge's; got {mode:g} (0 switches it off)")
    if mode and mode > 0.4 * spec.fs:
        fail("mismatch.gauge_mode_hz", f"must be at most 0.4 x fs ({0.4 * spec.fs:g} Hz) to be "
             f"simulated on the DAQ grid; got {mode:g}")
    return Unmodelled(**values)


def describe(knobs: Unmodelled) -> dict:
    """``{table.key: value}`` of the knobs that are set (for a log's ``meta``)."""
    return {k.name: getattr(knobs, k.field) for k in KNOBS if getattr(knobs, k.field) is not None}


def table_doc() -> str:
    """One line per knob (``rippleb sweep --help`` and docs)."""
    return "\n".join(f"{k.name}: {k.doc}; realistic {k.realistic:g}, off {k.off:g}" for k in KNOBS)


__all__ = ["KNOBS", "KNOB_BY_NAME", "Knob", "REALISTIC", "TABLES", "Unmodelled", "describe",
           "parse_tables", "table_doc"]
