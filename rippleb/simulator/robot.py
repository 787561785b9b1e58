"""The arm load: one joint of an ``example-robot-data`` arm through Pinocchio.

The model is built from the URDF alone (no meshes, no collision geometry), which keeps
the load of a model to about a millisecond after Pinocchio is imported.

Only one joint moves in a scenario; the others are held at the scenario's posture. For
such a motion the joint torque is exactly

    tau = M_jj(q) qdd + h(q) qd**2 + G_j(q)

because ``rnea`` is linear in the accelerations and quadratic in the velocities. The
three coefficients are tabulated with ``rnea`` on a fine grid of the moving joint's angle
and interpolated, so a scenario of any length costs a fixed number of ``rnea`` calls.
"""

from __future__ import annotations

import functools
import hashlib
from dataclasses import dataclass
from os.path import join

import numpy as np

from rippleb.errors import InputError

#: Grid points of the angle table. 2049 points over the trajectory's range keep the
#: linear interpolation error of the gravity torque below 1e-4 Nm on the UR5
#: (measured by ``tests/test_physics.py::test_load_table_matches_rnea``).
TABLE_POINTS = 2049

#: Relative spread (1 sigma) of the nominal model's link masses and rotational inertias
#: against the true ones: what an identification or a CAD model leaves. **Estimate**, see
#: docs/physics.md, "Nominal model of eq. (7)".
NOMINAL_MASS_SPREAD = 0.03
NOMINAL_INERTIA_SPREAD = 0.05
_NOMINAL_SALT = int.from_bytes(hashlib.sha256(b"nominal-model").digest()[:8], "little")


def robot_names() -> list[str]:
    """Names of the robots ``example-robot-data`` can load (those with a URDF)."""
    from example_robot_data import robots_loader

    return sorted(name for name, loader in robots_loader.ROBOTS.items()
                  if getattr(loader, "urdf_filename", ""))


def urdf_path(robot: str) -> str:
    """Path of the URDF of ``robot``, from the loader's class attributes.

    The loader class is not instantiated: that would build the geometry models too.
    """
    from example_robot_data import robots_loader

    loader = robots_loader.ROBOTS.get(robot)
    if loader is None or not getattr(loader, "urdf_filename", ""):
        raise InputError(f"unknown robot {robot!r}")
    relative = join(loader.path, loader.urdf_subpath, loader.urdf_filename)
    root = loader.model_path or robots_loader.getModelPath(relative)
    return join(root, relative)


@functools.lru_cache(maxsize=8)
def load_model(robot: str):
    """The Pinocchio model of ``robot`` built from its URDF, cached per process."""
    import pinocchio as pin

    return pin.buildModelFromUrdf(urdf_path(robot))


def nominal_model(robot: str, seed: int):
    """The model a robot's controller would use for the robot of ``seed``: the URDF's
    links with every mass and rotational inertia (about the centre of mass) off by
    independent normal relative errors of ``NOMINAL_MASS_SPREAD`` and
    ``NOMINAL_INERTIA_SPREAD``. Centres of mass and kinematics stay exact.

    The true robot is the URDF; the same seed always gives the same nominal model.
    """
    import pinocchio as pin

    model = load_model(robot).copy()
    rng = np.random.default_rng(np.random.SeedSequence([seed, _NOMINAL_SALT]))
    for i in range(1, model.njoints):
        link = model.inertias[i]
        mass_scale = 1.0 + NOMINAL_MASS_SPREAD * rng.standard_normal()
        inertia_scale = 1.0 + NOMINAL_INERTIA_SPREAD * rng.standard_normal()
        model.inertias[i] = pin.Inertia(link.mass * mass_scale, link.lever.copy(),
                                        link.inertia * inertia_scale)
    return model


def joint_names(robot: str) -> list[str]:
    """Names of the one-degree-of-freedom joints of ``robot``."""
    model = load_model(robot)
    return [model.names[i] for i in range(1, model.njoints) if model.joints[i].nq == 1 and model.joints[i].nv == 1]


@dataclass(frozen=True)
class LoadTable:
    """``M_jj``, ``h`` and ``G_j`` of one joint tabulated over its angle.

    Attributes
    ----------
    angle
        Grid of the moving joint's angle [rad].
    inertia, velocity_coeff, gravity
        ``M_jj`` [kg m^2], ``h`` [Nm s^2/rad^2] and ``G_j`` [Nm] on the grid.
    """

    angle: np.ndarray
    inertia: np.ndarray
    velocity_coeff: np.ndarray
    gravity: np.ndarray

    def torque(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
        """Joint torque [Nm] of the single-joint motion ``q, qd, qdd``."""
        return (np.interp(q, self.angle, self.inertia) * qdd
                + np.interp(q, self.angle, self.velocity_coeff) * qd * qd
                + np.interp(q, self.angle, self.gravity))

    def model_torque(self, q: np.ndarray, qdd: np.ndarray) -> np.ndarray:
        """The paper's eq. (7), ``M(q) qdd + G(q)`` [Nm], without velocity terms."""
        return (np.interp(q, self.angle, self.inertia) * qdd
                + np.interp(q, self.angle, self.gravity))


def load_table(robot: str, joint: str, posture: dict[str, float],
               q_range: tuple[float, float], points: int = TABLE_POINTS, model=None) -> LoadTable:
    """Tabulate the load of ``joint`` over ``q_range`` with the others at ``posture``.

    Parameters
    ----------
    robot, joint
        An ``example-robot-data`` robot and one of its revolute joints.
    posture
        Angles [rad] of the other joints; joints not named stay at zero.
    q_range
        Smallest and largest angle of the moving joint [rad]; the grid is padded a little.
    points
        Grid size.
    model
        The Pinocchio model to tabulate (default the true one of ``robot``; pass
        :func:`nominal_model` for the controller's).
    """
    import pinocchio as pin

    model = load_model(robot) if model is None else model
    data = model.createData()
    q0 = pin.neutral(model)
    for name, value in posture.items():
        q0[model.joints[model.getJointId(name)].idx_q] = value
    jid = model.getJointId(joint)
    iq, iv = model.joints[jid].idx_q, model.joints[jid].idx_v
    lo, hi = q_range
    pad = 1e-3 + 1e-3 * (hi - lo)
    grid = np.linspace(lo - pad, hi + pad, points)
    unit = np.zeros(model.nv)
    unit[iv] = 1.0
    zero = np.zeros(model.nv)
    gravity, inertia, velocity = (np.empty(points) for _ in range(3))
    for i, angle in enumerate(grid):
        q0[iq] = angle
        g = pin.rnea(model, data, q0, zero, zero)[iv]
        gravity[i] = g
        inertia[i] = pin.rnea(model, data, q0, zero, unit)[iv] - g
        velocity[i] = pin.rnea(model, data, q0, unit, zero)[iv] - g
    return LoadTable(grid, inertia, velocity, gravity)
