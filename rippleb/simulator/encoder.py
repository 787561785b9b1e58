"""The incremental encoder beyond an ideal code disc: edges that are not evenly spaced
within a count period, a disc that runs eccentric, and edges the DAQ's counter loses.

An ideal encoder counts ``floor(theta / 2 pi * cpr)``. A quadrature encoder makes its four
counts per line from the edges of two square waves, A and B; their duty cycles
(*symmetry*) and their phase (*quadrature*) are not exactly 180 and 90 electrical degrees,
so the four edges of each line sit off their nominal places, the same in every line: an
error periodic over four counts that the encoder's own resolution hides. The code disc is
mounted on the motor shaft with some eccentricity, which adds a once-per-revolution angle
error. Both are properties of the encoder, so they act on the count the position
controller reads (inside the compiled joint loop, :func:`rippleb.simulator.joint.integrate`)
and on the count the DAQ logs and the methods read (:func:`counts`), and on the index pulse
(gated to an A/B edge). Missed edges are the DAQ counter's (as the ``[faults]`` table's
``encoder_missed``, whose function this reuses), in the calibration log as in the scored
one. Magnitudes: ``docs/physics.md``, "Beyond the methods' models".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rippleb.simulator.conditions import stream

#: Symmetry (duty-cycle) error sigma as a multiple of the quadrature error sigma: US Digital
#: EM2 module datasheet limits, symmetry 180 +-72 electrical degrees, quadrature 90 +-45.
SYMMETRY_PER_QUADRATURE = 72.0 / 45.0
#: No edge moves more than this fraction of a count: beyond half a count the decoder's
#: states would change order, which the datasheet limits exclude.
MAX_EDGE_SHIFT = 0.45


@dataclass(frozen=True)
class EncoderErrors:
    """The errors of one device's encoder.

    Attributes
    ----------
    edges
        Shift [counts] of the edge that starts count ``n``, for ``n mod 4`` = 0..3
        (positive: the edge comes later in angle).
    eccentricity, phase
        Once-per-revolution angle error ``eccentricity sin(theta + phase)`` [rad].
    """

    edges: tuple[float, float, float, float]
    eccentricity: float
    phase: float

    @classmethod
    def draw(cls, seed: int, knobs, counts_per_rev: int) -> "EncoderErrors | None":
        """The errors of device ``seed`` at the sizes of ``knobs``; None for an ideal encoder.

        Quadrature error ``q ~ N(0, sigma)`` and symmetry errors of A and B ``s ~ N(0, 1.6
        sigma)`` [electrical deg], ``sigma = edge_error_deg``: A rises at ``-s_A/2``, B at
        ``90 + q - s_B/2``, A falls at ``180 + s_A/2``, B at ``270 + q + s_B/2``; 90
        electrical degrees are one count. The draws do not depend on the sizes.
        """
        if not knobs.encoder_active:
            return None
        q, s_a, s_b = stream(seed, "encoder-edges").standard_normal(3) * knobs.edge_error_deg
        s_a, s_b = SYMMETRY_PER_QUADRATURE * s_a, SYMMETRY_PER_QUADRATURE * s_b
        shifts = np.array([-s_a / 2, q - s_b / 2, s_a / 2, q + s_b / 2]) / 90.0
        shifts = np.clip(shifts, -MAX_EDGE_SHIFT, MAX_EDGE_SHIFT)
        phase = stream(seed, "encoder-eccentricity").uniform(0.0, 2 * np.pi)
        return cls(edges=tuple(float(s) for s in shifts),
                   eccentricity=knobs.eccentricity_counts * 2 * np.pi / counts_per_rev,
                   phase=float(phase))

    def params(self) -> dict:
        """The integrator's parameters (:data:`rippleb.simulator.joint.PARAMS`)."""
        e0, e1, e2, e3 = self.edges
        return dict(encoder_errors=1.0, edge0=e0, edge1=e1, edge2=e2, edge3=e3,
                    eccentricity=self.eccentricity, eccentricity_phase=self.phase)


#: The integrator's parameters of an ideal encoder.
IDEAL_PARAMS = dict(encoder_errors=0.0, edge0=0.0, edge1=0.0, edge2=0.0, edge3=0.0,
                    eccentricity=0.0, eccentricity_phase=0.0)


def counts(theta: np.ndarray, counts_per_rev: int, errors: EncoderErrors | None) -> np.ndarray:
    """Absolute encoder count [int64] at motor angle ``theta`` [rad].

    Without errors ``floor(theta / 2 pi * cpr)`` (today's expression, bit for bit). With
    them the disc reads ``theta + e sin(theta + phase)`` and count ``n`` starts at
    ``n + edges[n mod 4]`` counts: the same rule as the controller's
    (:func:`rippleb.simulator.joint.encoder_count`).
    """
    if errors is None:
        return np.floor(theta / (2 * np.pi) * counts_per_rev).astype(np.int64)
    x = (theta + errors.eccentricity * np.sin(theta + errors.phase)) / (2 * np.pi) * counts_per_rev
    n = np.floor(x)
    edges = np.asarray(errors.edges)
    before = x < n + edges[np.mod(n, 4).astype(np.int64)]
    after = x >= n + 1 + edges[np.mod(n + 1, 4).astype(np.int64)]
    return (n - before + after).astype(np.int64)


def missed_counts(encoder: np.ndarray, probability: float, seed: int, log_name: str) -> np.ndarray:
    """The DAQ counter losing each edge with ``probability``: the ``[faults]`` model of
    :func:`rippleb.simulator.sensors.encoder_faults`, in every session of the joint."""
    from rippleb.simulator.scenario import Faults
    from rippleb.simulator.sensors import encoder_faults

    rng = stream(seed, "encoder-missed", log_name)
    return encoder_faults(encoder, Faults(encoder_missed=probability), 1.0, rng)
