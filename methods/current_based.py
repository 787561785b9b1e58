"""``current-based``: joint torque from motor current with friction compensation.

The paper's comparison method (Sec. IV-B): "friction compensation based on the
conventional exponential model" and "the low-pass filter with 130 Hz of the cutoff
frequency". The motor shaft balances

    K_t i = tau / N + J_m a_m + F(w_m) + (load-dependent friction)

so the estimate is

    tau = N (K_t i - J_m a_m - F(w_m) - c) / (g + mu * sgn(w_m) * sgn(tau))

with the exponential (Stribeck) friction
``F(w) = [F_c + (F_s - F_c) exp(-(w / w_s)^2)] sgn(w) + b w`` on the motor shaft, a
constant ``c`` (current-sense offset), and a load-dependent part: ``mu`` makes the
Coulomb friction grow with the transmitted torque (gear efficiency differs between
driving and back-driving), ``g`` absorbs the part of that growth that is the same in
both directions and any error of the datasheet ``K_t`` (``g = 1`` for an ideal motor
and gear). ``K_t``, ``J_m`` and ``N`` come from the :class:`~rippleb.data.JointSpec`;
``F_c, F_s, w_s, b, c, g, mu`` are identified in :meth:`CurrentBased.fit` from the
calibration log alone.

Motor velocity and acceleration are causal estimates from the encoder: the count
difference per sample times ``fs`` through a second-order Butterworth low-pass at
``velocity_cutoff`` gives ``w_m``; its difference times ``fs`` through a second-order
Butterworth at ``accel_cutoff`` gives ``a_m``. At rest the friction direction is unknown
(static friction may hold any value up to ``F_s``), so ``sgn`` is replaced by
``clip(w / sign_width, -1, 1)``: no friction is compensated at rest. The result goes
through a second-order Butterworth low-pass at ``cutoff`` (130 Hz, the paper's).

Examples
--------
>>> CurrentBased().cutoff
130.0
"""

from __future__ import annotations

import numpy as np
from scipy import signal
from numba import types
from scipy.optimize import lsq_linear

from rippleb.data import JointSpec, SensorBlock, SensorLog
from rippleb.dsp import (F8, IN_F8, IN_I8, biquad, biquad_ss, compiled, encoder_angle,
                         steady_state)
from rippleb.method import Method


def stribeck(w: np.ndarray, coulomb: float, static: float, speed: float, viscous: float,
             sign: np.ndarray | None = None) -> np.ndarray:
    """The exponential friction model [Nm on the motor] at motor velocity ``w`` [rad/s].

    ``[F_c + (F_s - F_c) exp(-(w / w_s)^2)] sgn(w) + b w``; ``sign`` replaces
    ``sgn(w)`` when given (a smoothed sign at rest).
    """
    w = np.asarray(w, dtype=float)
    s = np.sign(w) if sign is None else sign
    return (coulomb + (static - coulomb) * np.exp(-(w / speed) ** 2)) * s + viscous * w


def soft_sign(w: np.ndarray, width: float) -> np.ndarray:
    """``sgn(w)`` outside ``|w| < width``, a linear ramp through zero inside it."""
    return np.clip(np.asarray(w, dtype=float) / width, -1.0, 1.0)


@compiled(types.float64(types.float64, types.float64, types.float64, IN_F8))
def joint_torque(current, w, acc, model):
    """Joint torque [Nm] of one sample: the friction model of the module docstring, inverted.

    ``current`` [A], motor velocity ``w`` [rad/s] and acceleration ``acc`` [rad/s^2];
    ``model`` holds ``K_t, J_m, N, fs, F_c, F_s, w_s, b, c, g, mu, sign_width``.
    """
    k_t, j_m, ratio = model[0], model[1], model[2]
    f_c, f_s, w_s, visc, offset, scale, mu, width = (model[4], model[5], model[6], model[7],
                                                     model[8], model[9], model[10], model[11])
    s = min(max(w / width, -1.0), 1.0)                       # soft_sign
    friction = (f_c + (f_s - f_c) * np.exp(-(w / w_s) ** 2)) * s + visc * w
    motor = k_t * current - j_m * acc - friction - offset
    # the load-dependent friction adds to the motor torque when the motor drives the
    # load (sgn tau = sgn w) and subtracts when the load back-drives the motor
    return ratio * motor / (scale + mu * s * np.sign(motor))


@compiled(types.void(IN_I8, IN_F8, types.int64, types.float64, IN_F8, IN_F8, IN_F8, IN_F8,
                    IN_F8, F8, F8))
def friction_torque(counts, current, last_count, rate_scale, velocity_b, velocity_a, accel_b,
                    accel_a, model, state, out):
    """Joint torque per sample: the motion estimator and the inverted friction model.

    Per sample: the count increment times ``rate_scale`` (``2 pi fs / counts_per_rev``)
    is the raw motor velocity; a biquad (``velocity_b, velocity_a``, transposed direct
    form II) gives ``w``; its difference times ``fs`` through a second biquad (``accel_b,
    accel_a``) gives ``a``; :func:`joint_torque` gives the torque.

    Parameters
    ----------
    counts, current
        The block's encoder counts and motor current [A].
    last_count
        The count of the sample before the block.
    model
        ``K_t, J_m, N, fs, ...``, as :func:`joint_torque` takes it.
    state
        ``(5,)``: the two velocity-filter states, the previous velocity, the two
        acceleration-filter states; updated in place.
    out
        The torque [Nm] per sample.
    """
    fs = model[3]
    v0, v1, w_prev, a0, a1 = state[0], state[1], state[2], state[3], state[4]
    for k in range(len(counts)):
        rate = (counts[k] - last_count) * rate_scale
        last_count = counts[k]
        w = velocity_b[0] * rate + v0
        v0 = velocity_b[1] * rate - velocity_a[1] * w + v1
        v1 = velocity_b[2] * rate - velocity_a[2] * w
        diff = fs * (w - w_prev)
        w_prev = w
        acc = accel_b[0] * diff + a0
        a0 = accel_b[1] * diff - accel_a[1] * acc + a1
        a1 = accel_b[2] * diff - accel_a[2] * acc
        out[k] = joint_torque(current[k], w, acc, model)
    state[0], state[1], state[2], state[3], state[4] = v0, v1, w_prev, a0, a1


def identify_friction(w, load, residual, speeds, sign_width, load_dependent=True):
    """Least-squares friction parameters, with ``w_s`` from a grid search.

    Parameters
    ----------
    w
        Motor velocity [rad/s] per sample (moving samples only).
    load
        Known joint torque over the gear ratio, ``tau / N`` [Nm on the motor].
    residual
        ``K_t i - J_m a_m`` [Nm on the motor].
    speeds
        Candidate Stribeck speeds ``w_s`` [rad/s].
    sign_width
        Width of the soft sign [rad/s].
    load_dependent
        If False, ``g = 1`` and ``mu = 0`` are fixed (the plain exponential model).

    Returns
    -------
    dict
        ``coulomb, static, speed, viscous, offset, scale, load`` (the ``F_c, F_s,
        w_s, b, c, g, mu`` of the module docstring) and ``rms`` of the fit [Nm].
    """
    s = soft_sign(w, sign_width)
    base = np.column_stack([s, w, np.ones_like(w), load, s * np.abs(load)])
    # physical bounds: F_c >= 0, b >= 0, 0 <= mu < g, F_s >= F_c; with one calibration
    # speed, Coulomb and viscous friction are nearly collinear and free signs wander
    lower = [0.0, 0.0, -np.inf, 0.5, 0.0, 0.0]
    upper = [np.inf, np.inf, np.inf, 2.0, 0.5, np.inf]
    if not load_dependent:
        lower[3:5], upper[3:5] = [1.0 - 1e-12, 0.0], [1.0 + 1e-12, 1e-12]
    best = None
    for speed in speeds:
        design = np.column_stack([base, s * np.exp(-(w / speed) ** 2)])
        # bounded least squares on the Cholesky factor of the (column-scaled) Gram
        # matrix: 6 unknowns, however long the log
        norm = np.linalg.norm(design, axis=0)
        scaled = design / norm
        chol = np.linalg.cholesky(scaled.T @ scaled)
        rhs = np.linalg.solve(chol, scaled.T @ residual)
        fit = lsq_linear(chol.T, rhs, bounds=(np.multiply(lower, norm), np.multiply(upper, norm)))
        coef = fit.x / norm
        rms = float(np.sqrt(np.mean((design @ coef - residual) ** 2)))
        if best is None or rms < best[0]:
            best = (rms, speed, coef)
    rms, speed, (fc, b, c, g, mu, ds) = best
    return dict(coulomb=fc, static=fc + ds, speed=speed, viscous=b, offset=c, scale=g,
                load=mu, rms=rms)


class CurrentBased(Method):
    """Motor-current torque estimate with exponential friction compensation.

    Parameters
    ----------
    cutoff
        Cut-off of the output low-pass [Hz]; 130 Hz in the paper.
    velocity_cutoff, accel_cutoff
        Cut-offs of the encoder velocity and acceleration low-passes [Hz] (60.2 and 22.5:
        the point the one tuning protocol adopted, ``methods/tuning.json``).
    sign_width
        Motor velocity [rad/s] below which the friction direction is taken as unknown
        and the compensation ramps to zero (1.42: the same adopted point's).
    load_dependent
        Identify the load-dependent Coulomb part ``mu`` and the scale ``g``; if False,
        ``g = 1`` and ``mu = 0`` (the plain exponential model).

    Where the defaults come from is in ``docs/methods/current-based.md``.
    """

    name = "current-based"
    description = ("motor current minus identified friction and inertia, then a low-pass "
                   "(cutoff=130.0), as in the paper's comparison")
    #: ranges of the tuning protocol (rippleb/tuning.py); ``cutoff`` is the paper's 130 Hz
    tunable = {"velocity_cutoff": (50.0, 800.0, "log"), "accel_cutoff": (5.0, 100.0, "log"),
               "sign_width": (0.1, 2.0, "log")}

    def __init__(self, cutoff=130.0, velocity_cutoff=60.2, accel_cutoff=22.5, sign_width=1.42,
                 load_dependent=True):
        self.cutoff = cutoff
        self.velocity_cutoff = velocity_cutoff
        self.accel_cutoff = accel_cutoff
        self.sign_width = sign_width
        self.load_dependent = load_dependent

    # -- identification --------------------------------------------------------------
    def fit(self, calibration: SensorLog) -> None:
        """Identify the friction model from the calibration log and its known torque.

        Velocity and acceleration are the zero-phase (forward-backward) versions of
        the streaming estimators: offline, the fit need not suffer their delay.
        """
        spec = calibration.spec
        w, a = self._offline_motion(calibration.encoder, spec)
        load = np.asarray(calibration.torque_ref, dtype=float) / spec.gear_ratio
        residual = spec.torque_constant * np.asarray(calibration.current) - spec.rotor_inertia * a
        moving = np.abs(w) > self.sign_width
        speeds = np.geomspace(0.2, 50.0, 40)
        if moving.sum() < 10:
            raise ValueError("current-based: the calibration log has no motion to identify friction")
        if not ((w[moving] > 0).any() and (w[moving] < 0).any()):
            # Coulomb friction is sign(w) times a constant: in one direction it equals the
            # current offset, and the least-squares problem has no unique solution.
            raise ValueError("current-based: cannot identify friction: the calibration log turns the "
                             "joint in one direction only, so Coulomb friction and the current offset "
                             "cannot be told apart; calibrate on a log that moves both ways over a "
                             "range of speeds (e.g. --calibration from 'rippleb simulate calibration')")
        # the motion estimates are band-limited to tens of Hz: a 2 kHz subsample holds
        # all their information and keeps the fit fast on long logs
        moving[np.arange(len(moving)) % 10 != 0] = False
        self.friction_ = identify_friction(w[moving], load[moving], residual[moving], speeds,
                                           self.sign_width, self.load_dependent)

    def _offline_motion(self, encoder: np.ndarray, spec: JointSpec):
        """Zero-phase motor velocity and acceleration of a whole log."""
        angle = encoder_angle(encoder, spec.counts_per_rev)
        rate = np.diff(angle, prepend=angle[0]) * spec.fs
        b_v, a_v = signal.butter(2, self.velocity_cutoff, fs=spec.fs)
        w = signal.filtfilt(b_v, a_v, rate)
        b_a, a_a = signal.butter(2, self.accel_cutoff, fs=spec.fs)
        a = signal.filtfilt(b_a, a_a, np.gradient(w) * spec.fs)
        return w, a

    # -- streaming -------------------------------------------------------------------
    def reset(self, spec: JointSpec) -> None:
        """Design the estimator and output filters for ``spec`` and clear their state."""
        super().reset(spec)
        if not hasattr(self, "friction_"):
            self.friction_ = dict(coulomb=0.0, static=0.0, speed=1.0, viscous=0.0, offset=0.0,
                                  scale=1.0, load=0.0)
        f = self.friction_
        self.model_ = np.array([spec.torque_constant, spec.rotor_inertia, spec.gear_ratio, spec.fs,
                                f["coulomb"], f["static"], f["speed"], f["viscous"], f["offset"],
                                f["scale"], f["load"], self.sign_width], dtype=float)
        self.velocity_ = signal.butter(2, self.velocity_cutoff, fs=spec.fs)
        self.accel_ = signal.butter(2, self.accel_cutoff, fs=spec.fs)
        self.output_ = signal.butter(2, self.cutoff, fs=spec.fs)
        self.rate_scale_ = 2.0 * np.pi / spec.counts_per_rev * spec.fs
        self.x_motion_ = np.zeros(5)
        self.x_out_ = None               # output low-pass state, set on the first sample
        self.last_count_ = None

    def step(self, block: SensorBlock) -> np.ndarray:
        """Friction-compensated current torque of ``block``, low-passed."""
        counts = np.asarray(block.encoder, dtype=np.int64)
        if len(counts) == 0:
            return np.zeros(0)
        if self.last_count_ is None:
            self.last_count_ = int(counts[0])
        tau = np.empty(len(counts))
        friction_torque(counts, np.asarray(block.current, dtype=float), self.last_count_,
                        self.rate_scale_, *self.velocity_, *self.accel_, self.model_,
                        self.x_motion_, tau)
        self.last_count_ = int(counts[-1])
        if self.x_out_ is None:
            self.x_out_ = steady_state(*biquad_ss(*self.output_)[:2], tau[0])
        biquad(*self.output_, tau, self.x_out_, tau)
        return tau
