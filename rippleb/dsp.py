"""Small signal-processing helpers shared by several methods and the metrics.

The per-sample recursions of the methods are plain loops compiled by numba
(:data:`compiled`): one readable reference implementation that costs a few microseconds
per control tick and is linear in the block length. Each is compiled for the one
signature it is called with when its module is imported (or loaded from numba's on-disk
cache), so the runner's forked children inherit the machine code instead of compiling
it again per row.
"""

from __future__ import annotations

import os

import numba
import numpy as np
from numba import types

#: Argument types of the compiled kernels: 1-d float64 / int64 input arrays (read-only
#: accepted, so log columns go in without a copy) and float64 arrays written in place.
IN_F8 = types.Array(types.float64, 1, "A", readonly=True)
IN_I8 = types.Array(types.int64, 1, "A", readonly=True)
IN_F8_2D = types.Array(types.float64, 2, "A", readonly=True)
F8 = types.float64[:]
F8_2D = types.float64[:, :]
#: C-contiguous float64 arrays written in place (work arrays a kernel allocates or owns).
F8_C = types.float64[::1]
F8_2D_C = types.float64[:, ::1]


def compiled(signature):
    """``numba.njit`` for ``signature``, compiled at import and cached on disk.

    numba caches beside the function's source, else under ``$HOME`` (or ``NUMBA_CACHE_DIR``);
    where neither is writable (an unprivileged user without a home, issue 41: a "cannot cache
    function" traceback before any row ran) it caches in a directory of this user's own
    under the system's temporary directory (:func:`private_cache_dir`), and where even that
    cannot be had, compiles without caching (each process compiles again)."""
    def decorate(fn):
        try:
            return numba.njit(signature, cache=True, nogil=True)(fn)
        except RuntimeError:   # "no locator available": nowhere numba may write its cache
            from numba.core import config

            config.CACHE_DIR = private_cache_dir() or config.CACHE_DIR
            try:
                return numba.njit(signature, cache=True, nogil=True)(fn)
            except RuntimeError:
                return numba.njit(signature, nogil=True)(fn)
    return decorate


def private_cache_dir() -> str | None:
    """``<temporary directory>/rippleb-numba-<uid>``, made mode 0700, if it is this user's own
    directory (not a link, not another user's, not open to others); else None."""
    import stat
    import tempfile

    path = os.path.join(tempfile.gettempdir(), f"rippleb-numba-{os.getuid()}")
    try:
        os.mkdir(path, 0o700)
    except FileExistsError:
        pass
    except OSError:
        return None
    info = os.lstat(path)
    if not stat.S_ISDIR(info.st_mode) or info.st_uid != os.getuid() or info.st_mode & 0o077:
        return None
    return path


def fit_gain_offset(strain: np.ndarray, torque: np.ndarray) -> tuple[float, float]:
    """Least-squares ``torque ~= gain * strain + offset``.

    On a calibration log that spans many wave-generator revolutions the ripple, being
    zero-mean over a revolution, averages out of the fit.

    Returns
    -------
    gain, offset
        In Nm/V and Nm.
    """
    design = np.column_stack([strain, np.ones_like(strain)])
    (gain, offset), *_ = np.linalg.lstsq(design, torque, rcond=None)
    return float(gain), float(offset)


def encoder_angle(counts: np.ndarray, counts_per_rev: int) -> np.ndarray:
    """Motor (wave-generator) angle [rad] from encoder counts."""
    return np.asarray(counts, dtype=float) * (2.0 * np.pi / counts_per_rev)


def steady_state(A: np.ndarray, B: np.ndarray, u0: float) -> np.ndarray:
    """State of ``x[k+1] = A x + B u`` held at the constant input ``u0`` for ever.

    Starting a filter there instead of at zero avoids the cold-start transient of a
    step from zero to the first sample (the analogue of ``scipy.signal.lfilter_zi``).
    """
    A = np.atleast_2d(np.asarray(A, dtype=float))
    return np.linalg.solve(np.eye(A.shape[0]) - A, np.asarray(B, dtype=float).reshape(-1) * u0)


def biquad_ss(b: np.ndarray, a: np.ndarray):
    """State space (A, B, C, D) of one biquad in transposed direct form II.

    The transposed direct form keeps low-frequency notches (poles close to 1 at a
    20 kHz sample rate) well conditioned, unlike a high-order transfer function.
    """
    b = np.asarray(b, dtype=float) / a[0]
    a = np.asarray(a, dtype=float) / a[0]
    A = np.array([[-a[1], 1.0], [-a[2], 0.0]])
    B = np.array([b[1] - a[1] * b[0], b[2] - a[2] * b[0]])
    return A, B, np.array([[1.0, 0.0]]), np.array([b[0]])


def series_ss(*systems):
    """State space of single-input single-output systems in series (first one first)."""
    A, B, C, D = systems[0]
    for A2, B2, C2, D2 in systems[1:]:
        n1, n2 = A.shape[0], A2.shape[0]
        A = np.block([[A, np.zeros((n1, n2))], [np.outer(B2, C[0]), A2]])
        B = np.concatenate([B, B2 * D[0]])
        C = np.concatenate([D2[0] * C[0], C2[0]])[None, :]
        D = D2 * D[0]
    return A, B, C, D


@compiled(types.void(IN_F8, IN_F8, IN_F8, F8, F8))
def biquad(b, a, x, state, out):
    """One second-order section in transposed direct form II over ``x``, into ``out``.

    The recursion of ``scipy.signal.lfilter(b, a, x, zi=state)`` for three coefficients
    each (``a[0] == 1``); ``state`` (2,) is updated in place, in ``lfilter``'s
    convention, so either can continue the other. ``out`` may be ``x``.
    """
    z0, z1 = state[0], state[1]
    for k in range(len(x)):
        u = x[k]
        y = b[0] * u + z0
        z0 = b[1] * u - a[1] * y + z1
        z1 = b[2] * u - a[2] * y
        out[k] = y
    state[0], state[1] = z0, z1


@compiled(types.void(F8_2D_C, F8_2D_C))
def cholesky(A, L):
    """Lower Cholesky factor ``L`` of the symmetric positive definite ``A`` (``A = L L'``).

    Written out rather than numba's ``np.linalg.cholesky``: at the 30 x 30 of
    ``angle-adaptive``'s map the LAPACK call's overhead outweighs the arithmetic (measured
    2.5 us against 3.7 us per call). Only the lower triangle of ``L`` is written.
    """
    for j in range(A.shape[0]):
        total = A[j, j]
        for k in range(j):
            total -= L[j, k] * L[j, k]
        L[j, j] = np.sqrt(total)
        for i in range(j + 1, A.shape[0]):
            total = A[i, j]
            for k in range(j):
                total -= L[i, k] * L[j, k]
            L[i, j] = total / L[j, j]


@compiled(types.void(F8_2D_C, F8_C))
def forward_substitute(L, x):
    """``x <- L^-1 x`` for the lower triangular ``L``, in place."""
    for i in range(len(x)):
        total = x[i]
        for k in range(i):
            total -= L[i, k] * x[k]
        x[i] = total / L[i, i]


@compiled(types.void(F8_2D_C, F8_C))
def backward_substitute(L, x):
    """``x <- L'^-1 x`` for the lower triangular ``L``, in place."""
    for i in range(len(x) - 1, -1, -1):
        total = x[i]
        for k in range(i + 1, len(x)):
            total -= L[k, i] * x[k]
        x[i] = total / L[i, i]
