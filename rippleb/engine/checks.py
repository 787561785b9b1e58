"""Range checks of options and inputs: one :class:`~rippleb.errors.InputError` line each.

Options (job count, timeout, memory limit), scenarios (finite posture and trajectory,
position and velocity limits of the URDF joint, physical bounds) and recorded logs (the sample
rate given by ``t``, the length a log needs to be scored; a calibration log's length, rate and
reference).
"""

from __future__ import annotations

import math

import numpy as np

from rippleb.data import SensorLog
from rippleb.errors import InputError
from rippleb.scoring.metrics import MAX_DELAY_S
from rippleb.timebase import uniform_rate
from rippleb.engine.rows import check_trajectory

MIN_FS, MAX_FS = 100.0, 1e6
MIN_CALIBRATION_S = 1.0
#: Shortest recording that can be scored [s]: twice the 100 ms of lags ``delay_ms`` searches
#: (:data:`rippleb.scoring.metrics.MAX_DELAY_S`), so that at its largest lag the estimate and the
#: reference still overlap for as long as they are shifted; 4000 samples at 20 kHz.
MIN_SCORED_S = 2 * MAX_DELAY_S


#: The largest ``--memory-limit`` [MB] a worker can be held to: 128 TiB, the whole address
#: space of a process on x86-64 Linux (47 bits). A larger cap limits nothing, and far larger
#: ones (1e13 MB) overflow the kernel's 64-bit ``RLIMIT_AS``, which every job then failed
#: on (issue 34: a run of `error` rows instead of one line).
MAX_MEMORY_MB = 2.0**27


def check_options(*, jobs, timeout, memory_mb) -> None:
    """Refuse a job count below 1, a negative or non-finite timeout or memory limit, and
    a memory limit above :data:`MAX_MEMORY_MB`."""
    if isinstance(jobs, bool) or not isinstance(jobs, (int, np.integer)) or jobs < 1:
        raise InputError(f"--jobs must be a whole number of at least 1, got {jobs!r}")
    for option, value, unit in (("--timeout", timeout, "seconds"), ("--memory-limit", memory_mb, "MB")):
        if value is not None and not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
            raise InputError(f"{option} must be a positive number of {unit} (0 for no limit), got {value!r}")
    if memory_mb is not None and memory_mb > MAX_MEMORY_MB:
        raise InputError(f"--memory-limit {memory_mb:g} MB is more than the {MAX_MEMORY_MB:.0f} MB (128 TiB) "
                         f"address space of a process: the kernel cannot hold a job to it; give 0 for no limit")


def check_scenario(scenario) -> None:
    """Refuse a scenario outside the joint's position or speed limits, or not finite, or
    out of physical bounds (:mod:`rippleb.simulator.validity`): the segment and load counts,
    posture and loads first, as the trajectory's dense sampling costs segments squared; the
    exact peak speed and acceleration of each segment last."""
    from rippleb.simulator import robot as arm
    from rippleb.simulator.validity import check_bounds, check_motion

    model = arm.load_model(scenario.robot)
    joint = model.joints[model.getJointId(scenario.joint)]
    check_bounds(scenario, model)
    check_trajectory(scenario, float(model.velocityLimit[joint.idx_v]))
    check_motion(scenario, model)


def check_recording(log: SensorLog, name: str) -> None:
    """Refuse a recorded log whose sample rate (from ``t``) is implausible."""
    fs = rate_from_t(log)
    if not MIN_FS <= fs <= MAX_FS:
        hint = " (is t in seconds?)" if fs < MIN_FS else ""
        raise InputError(f"{name}: column t gives a sample rate of {fs:.6g} Hz, outside the plausible "
                         f"{MIN_FS:g} Hz - {MAX_FS:g} Hz for a joint torque sensor{hint}")


def check_scored_length(log: SensorLog, name: str) -> None:
    """Refuse a recording too short to score (:data:`MIN_SCORED_S`)."""
    fs = rate_from_t(log)
    needed = math.ceil(MIN_SCORED_S * fs - 1e-6)
    if len(log) < needed:
        raise InputError(f"{name}: {len(log)} samples ({len(log) / fs:.3g} s) is too short to score; a log "
                         f"needs at least {MIN_SCORED_S:g} s ({needed} samples at {fs:.6g} Hz), twice the "
                         f"{1000 * MAX_DELAY_S:g} ms of lags delay_ms searches")


def check_reference(cal: SensorLog, name: str) -> None:
    """Refuse a calibration log whose ``torque_ref`` never changes: a method fits its gain
    against it, and a constant (an all-zero column) gives it nothing to fit."""
    ref = cal.torque_ref
    if ref is not None and len(ref) and ref.min() == ref.max():
        raise InputError(f"{name}: column torque_ref is {ref[0]:g} Nm throughout; a calibration needs a "
                         f"reference torque that varies (methods fit their gain against it)")


def check_calibration(cal: SensorLog, name: str, scored: SensorLog) -> None:
    """Refuse a calibration log too short to fit on, or recorded at another rate than the scored log."""
    seconds = (cal.t[-1] - cal.t[0]) if len(cal) > 1 else 0.0
    if seconds < MIN_CALIBRATION_S:
        raise InputError(f"{name}: {len(cal)} samples ({seconds:.3g} s) is too short to calibrate on; "
                         f"record at least {MIN_CALIBRATION_S:g} s with the joint moving")
    fs, scored_fs = rate_from_t(cal), rate_from_t(scored)
    if not math.isclose(fs, scored_fs, rel_tol=1e-3):
        raise InputError(f"{name}: recorded at {fs:.6g} Hz, the scored log at {scored_fs:.6g} Hz; "
                         f"record both at one rate")


def check_strain_scale(log: SensorLog, cal: SensorLog, name: str) -> None:
    """Refuse a scored log whose strain, calibrated as the calibration log's, is no torque of
    the joint (:func:`rippleb.joint_checks.check_strain_scale`): its unit differs."""
    from rippleb.data import MAX_TORQUE_FACTOR
    from rippleb.joint_checks import check_strain_scale as check

    check(log.strain, cal, MAX_TORQUE_FACTOR * log.spec.rated_torque, name,
          log.meta.get("columns", {}).get("strain", "as given"))


def rate_from_t(log: SensorLog) -> float:
    """The sample rate [Hz] given by the log's time stamps, their mean rate
    (:func:`rippleb.timebase.uniform_rate`: robust to Unix time's quantized steps); its
    spec's ``fs`` if it has one sample."""
    if len(log) < 2:
        return float(log.spec.fs)
    return uniform_rate(log.t)
