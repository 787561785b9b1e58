"""The joint's mechanics: the drive's torsional compliance and the arm load it carries.

The arm load comes from :mod:`rippleb.simulator.robot` (Pinocchio), tabulated over the
moving joint's angle; the nominal model of eq. (7) is the same arm with identification
errors (:func:`rippleb.simulator.robot.nominal_model`).
"""

from __future__ import annotations

import numpy as np

from rippleb.errors import InputError
from rippleb.simulator import robot

# --- harmonic drive stiffness, size 25: a smooth fit of the catalogue's K1/K3 curve ---
STIFFNESS_LOW = 3.1e4        # Nm/rad near zero torque (catalogue K1)
STIFFNESS_HIGH = 5.7e4       # Nm/rad at high torque (catalogue K3)
STIFFNESS_KNEE = 22.0        # Nm: where the stiffness has moved half-way; fit, see physics.md

def twist(torque: np.ndarray) -> np.ndarray:
    """Torsional deflection of the drive [rad] under ``torque``.

    ``tau / K_high + (1/K_low - 1/K_high) T_knee tanh(tau / T_knee)``: stiffness
    ``K_low`` at zero torque rising smoothly to ``K_high``. Smooth, because the motor
    acceleration follows the second derivative of the twist; the catalogue's
    piecewise-linear curve would put impulses into the motor current at its corners.
    """
    soft = 1.0 / STIFFNESS_LOW - 1.0 / STIFFNESS_HIGH
    return torque / STIFFNESS_HIGH + soft * STIFFNESS_KNEE * np.tanh(torque / STIFFNESS_KNEE)



def load_table(sc: Scenario, q: np.ndarray, nominal_seed: int | None = None):
    """The true load table of the scenario's joint, or with ``nominal_seed`` the one of
    the nominal model (:func:`rippleb.simulator.robot.nominal_model`) of that robot."""
    model = robot.load_model(sc.robot)
    idx = model.joints[model.getJointId(sc.joint)].idx_q
    lo, hi = float(q.min()), float(q.max())
    if lo < model.lowerPositionLimit[idx] or hi > model.upperPositionLimit[idx]:
        raise InputError(f"{sc.path}: trajectory: {sc.joint} travels over [{lo:.3f}, {hi:.3f}] rad, "
                         f"outside its limits [{model.lowerPositionLimit[idx]:.3f}, "
                         f"{model.upperPositionLimit[idx]:.3f}]")
    model = None if nominal_seed is None else robot.nominal_model(sc.robot, nominal_seed)
    return robot.load_table(sc.robot, sc.joint, dict(sc.posture), (lo, hi), model=model)
