"""Scalar linear-algebra kernels for the compiled filter steps (numba, ``nopython``).

A sequential filter on a few states spends its time in the overheads of numpy calls on tiny
arrays (about 1 us a call, some 75 calls a UKF step). The compiled steps (:mod:`localization.compiled.ukf`,
the dead-reckoning kernel) run the whole step in one call instead, and share these small
kernels. Each works on one run: a vector ``(n,)`` or a matrix ``(n, n)`` of float64, written
into a caller's buffer so that a batch loop allocates nothing. The numpy implementations in
:mod:`localization.linalg` and the filters stay the reference the compiled steps are tested
against.

All functions are compiled with ``cache=True`` (the machine code is kept beside the module,
or in numba's user cache when that folder is read-only), so only the first import on a
machine pays the compilation.
"""

from __future__ import annotations

import math

import numba

TWO_PI = 2.0 * math.pi


@numba.njit(cache=True, inline="always")
def wrap_angle(angle_rad: float) -> float:
    """``angle_rad`` wrapped to ``[-pi, pi)`` (the same formula as :func:`localization.linalg.wrap_angle`).

    The common case, ``angle_rad + pi`` already in ``[0, 2 pi)``, skips the modulo (a call of
    ``fmod``), which returns its argument there: the same result bit for bit.
    """
    shifted = angle_rad + math.pi
    if 0.0 <= shifted < TWO_PI:
        return shifted - math.pi
    wrapped = shifted % TWO_PI - math.pi
    if wrapped >= math.pi:
        wrapped -= TWO_PI
    return wrapped


@numba.njit(cache=True)
def wrap_residual(angle_rad: float) -> float:
    """An angle difference wrapped to ``[-pi, pi]`` (as :func:`localization.linalg.wrap_residual`)."""
    return angle_rad - TWO_PI * round(angle_rad / TWO_PI)


@numba.njit(cache=True)
def cholesky_lower(matrix, out) -> bool:
    """Lower Cholesky factor ``L L^T = matrix (n, n)`` into ``out (n, n)`` (upper part zeroed).

    Reads only the lower triangle of ``matrix``. Returns ``False`` (``out`` then undefined) when
    a pivot is not positive and finite, i.e. the matrix is not positive definite to working
    precision, as LAPACK ``dpotrf`` decides.
    """
    n = matrix.shape[0]
    for j in range(n):
        pivot = matrix[j, j]
        for k in range(j):
            pivot -= out[j, k] * out[j, k]
        if not (pivot > 0.0) or not math.isfinite(pivot):
            return False
        diagonal = math.sqrt(pivot)
        out[j, j] = diagonal
        for i in range(j + 1, n):
            total = matrix[i, j]
            for k in range(j):
                total -= out[i, k] * out[j, k]
            out[i, j] = total / diagonal
        for i in range(j):
            out[i, j] = 0.0
    return True


@numba.njit(cache=True)
def cholesky_solve(factor, rhs, out) -> None:
    """``out (m, r) = A^-1 rhs`` for ``A = factor factor^T`` (``factor (m, m)`` from :func:`cholesky_lower`).

    Forward then back substitution, column by column; ``out`` may be ``rhs`` (in place).
    """
    m = factor.shape[0]
    for c in range(rhs.shape[1]):
        for i in range(m):  # L y = b
            total = rhs[i, c]
            for k in range(i):
                total -= factor[i, k] * out[k, c]
            out[i, c] = total / factor[i, i]
        for i in range(m - 1, -1, -1):  # L^T x = y
            total = out[i, c]
            for k in range(i + 1, m):
                total -= factor[k, i] * out[k, c]
            out[i, c] = total / factor[i, i]


@numba.njit(cache=True)
def all_finite(values) -> bool:
    """Whether every entry of a float array is finite.

    ``value * 0`` is 0 for a finite value and NaN for an infinite or NaN one, so the sum is 0
    exactly when all are finite: one pass without a branch a value, no temporary array, and
    ``flat`` rather than ``ravel()`` (a call of numba's reshape helper, about 50 ns).
    """
    total = 0.0
    for value in values.flat:
        total += value * 0.0
    return total == 0.0


@numba.njit(cache=True)
def gain_from_cross(s_cov, cross, s_chol, gain_t) -> bool:
    """``gain_t (m, n) = S^-1 C^T`` (the transposed Kalman gain) from ``s_cov (m, m) = S`` and
    ``cross (n, m) = C``, by a Cholesky factor ``s_chol`` of ``S``; ``False`` when ``S`` is not
    positive definite."""
    if not cholesky_lower(s_cov, s_chol):
        return False
    for c in range(s_cov.shape[0]):
        for i in range(cross.shape[0]):
            gain_t[c, i] = cross[i, c]
    cholesky_solve(s_chol, gain_t, gain_t)
    return True


@numba.njit(cache=True)
def kalman_gain_t(cov, jac, noise_cov, cross, s_cov, s_chol, gain_t) -> bool:
    """The transposed Kalman gain of a linearised update, ``K^T = S^-1 (P H^T)^T``.

    ``cov (n, n)`` the prior ``P``, ``jac (m, n)`` the measurement matrix ``H``, ``noise_cov
    (m, m)`` ``R``. Writes ``cross (n, m) = P H^T``, ``s_cov (m, m) = S = H P H^T + R``, its
    Cholesky factor ``s_chol`` and ``gain_t (m, n)``. Returns ``False`` (buffers then undefined
    past ``s_cov``) when ``S`` is not positive definite.
    """
    n, m = cov.shape[0], jac.shape[0]
    for i in range(n):  # P H^T
        for c in range(m):
            total = 0.0
            for k in range(n):
                total += cov[i, k] * jac[c, k]
            cross[i, c] = total
    for c in range(m):  # S = H (P H^T) + R
        for d in range(m):
            total = 0.0
            for k in range(n):
                total += jac[c, k] * cross[k, d]
            s_cov[c, d] = total + noise_cov[c, d]
    return gain_from_cross(s_cov, cross, s_chol, gain_t)


@numba.njit(cache=True)
def symmetrise_in_place(matrix) -> None:
    """``matrix (n, n) = (matrix + matrix^T) / 2`` in place (exactly symmetric)."""
    n = matrix.shape[0]
    for i in range(n):
        for j in range(i):
            value = 0.5 * (matrix[i, j] + matrix[j, i])
            matrix[i, j] = value
            matrix[j, i] = value
