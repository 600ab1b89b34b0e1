"""The batched UKF step of the built-in models in structure-of-arrays layout (numba).

A batch's beliefs come as an array of structures, ``mean (B, n)``, ``cov (B, n, n)``. The
entries here step them a block of :data:`RUN_BLOCK` runs at a time with the runs innermost:
the block gathered into ``x (n, b)``, ``P (n, n, b)``, its sigma points, images and moments
held as ``(..., b)``, every loop over the block's runs last, so that LLVM vectorises the
arithmetic across runs (no fastmath: the operations stay those written). Each run goes
through exactly the operations of the per-run functions of :mod:`localization.compiled.ukf`
(:func:`~localization.compiled.ukf.predict_run`,
:func:`~localization.compiled.ukf.augmented_predict_run`,
:func:`~localization.compiled.ukf.update_run` with the built-in kernels), in the same order;
only the order across runs changes, so a run's result is theirs bit for bit (tested in
``tests/localization/test_compiled_soa.py``). The maths is documented there (paper 001 eq.
25-35); the motion models are the scalar functions of :mod:`localization.compiled.motion`
(``*_scalar``, ``*_noisy_scalar``), called per run. The results are written straight into
the caller's ``(B, n)`` / ``(B, n, n)`` outputs. The entries (:func:`predict_builtin`,
:func:`noisy_predict_builtin`, :func:`update_leading_entries`) are those of the built-in
kernels in :data:`localization.compiled.ukf.PREDICT_ENTRIES` and ``UPDATE_ENTRIES``; a user's
kernel (an array function) and one run of the lean filters take the per-run functions.

Status. Every run gets its status as the per-run functions decide it, in their order
(update: ``z`` not finite, then ``P`` not positive definite, then ``S``, then a result not
finite; prediction: ``P``, then the result); a run that fails is computed on to the end of its
block (NaNs; ``error_model="numpy"``, so a zero pivot divides instead of raising) and the
entry returns the first status that is not ``OK`` in run order, as the per-run loop of
:mod:`localization.compiled.batch` does (the outputs are then to be discarded).

Arguments as :mod:`localization.compiled.ukf`'s entries: ``args (B or 1, k)``, whose first
column is ``dt_s`` (the built-in kernels read only that), the noise ``(B or 1, q, q)`` shared
or per run.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from localization.compiled import motion
from localization.compiled.glue import NOT_FINITE, NOT_POSITIVE_DEFINITE, OK
from localization.compiled.linalg import all_finite, wrap_angle, wrap_residual

#: Runs a block: its scratch (the augmented CTRA's images ``16 x 6 x 64`` floats, 48 kB, the
#: largest) stays near the core.
RUN_BLOCK = 64

_jit = numba.njit(cache=True, error_model="numpy")


@_jit
def _gather(mean, cov, start, count, x, prior) -> None:
    """``x (n, b)``, ``prior (n, n, b)``: runs ``start .. start + count - 1`` of ``mean (B, n)``,
    ``cov (B, n, n)``."""
    n = x.shape[0]
    for c in range(count):
        for j in range(n):
            x[j, c] = mean[start + c, j]
            for k in range(n):
                prior[j, k, c] = cov[start + c, j, k]


@_jit
def _cholesky(matrix, count, out, pd) -> None:
    """:func:`localization.compiled.linalg.cholesky_lower` of each run ``c < count`` of
    ``matrix (n, n, b)`` into ``out (n, n, b)``; ``pd[c]`` cleared where a pivot is not positive
    and finite (that run's factor is then garbage, NaN)."""
    n = matrix.shape[0]
    for j in range(n):
        for c in range(count):
            out[j, j, c] = matrix[j, j, c]
        for k in range(j):
            for c in range(count):
                out[j, j, c] -= out[j, k, c] * out[j, k, c]
        for c in range(count):
            pivot = out[j, j, c]
            pd[c] = pd[c] and pivot > 0.0 and math.isfinite(pivot)
            out[j, j, c] = math.sqrt(pivot)
        for i in range(j + 1, n):
            for c in range(count):
                out[i, j, c] = matrix[i, j, c]
            for k in range(j):
                for c in range(count):
                    out[i, j, c] -= out[i, k, c] * out[j, k, c]
            for c in range(count):
                out[i, j, c] = out[i, j, c] / out[j, j, c]
        for i in range(j):
            for c in range(count):
                out[i, j, c] = 0.0


@_jit
def _images(model, augmented, point, noise, dt, count, out) -> None:
    """``out[:, c]`` the transition of ``point[:, c]`` (with the increments ``noise[:, c]`` when
    ``augmented``) over ``dt[c]`` by the built-in model number ``model``
    (:data:`~localization.compiled.motion.MODEL_NUMBERS`), as its ``*_point`` kernel."""
    p, e = point, noise
    if model == 0 and augmented:
        for c in range(count):
            out[0, c], out[1, c], out[2, c], out[3, c] = motion.cv_noisy_scalar(
                p[0, c], p[1, c], p[2, c], p[3, c], e[0, c], e[1, c], dt[c]
            )
    elif model == 0:
        for c in range(count):
            out[0, c], out[1, c] = motion.cv_scalar(p[0, c], p[1, c], p[2, c], p[3, c], dt[c])
            out[2, c], out[3, c] = p[2, c], p[3, c]
    elif model == 1 and augmented:
        for c in range(count):
            out[0, c], out[1, c], out[2, c], out[3, c], out[4, c] = motion.ctrv_noisy_scalar(
                p[0, c], p[1, c], p[2, c], p[3, c], p[4, c], e[0, c], e[1, c], dt[c]
            )
    elif model == 1:
        for c in range(count):
            out[0, c], out[1, c], out[2, c] = motion.ctrv_scalar(
                p[0, c], p[1, c], p[2, c], p[3, c], p[4, c], dt[c]
            )
            out[3, c], out[4, c] = p[3, c], p[4, c]
    elif model == 2 and augmented:
        for c in range(count):
            (out[0, c], out[1, c], out[2, c], out[3, c], out[4, c], out[5, c]) = (
                motion.ctra_noisy_scalar(
                    p[0, c], p[1, c], p[2, c], p[3, c], p[4, c], p[5, c], e[0, c], e[1, c], dt[c]
                )
            )
    elif model == 2:
        for c in range(count):
            out[0, c], out[1, c], out[2, c], out[3, c] = motion.ctra_scalar(
                p[0, c], p[1, c], p[2, c], p[3, c], p[4, c], p[5, c], dt[c]
            )
            out[4, c], out[5, c] = p[4, c], p[5, c]
    elif augmented:
        for c in range(count):
            (out[0, c], out[1, c], out[2, c], out[3, c], out[4, c], out[5, c]) = (
                motion.cca_noisy_scalar(
                    p[0, c], p[1, c], p[2, c], p[3, c], p[4, c], p[5, c], e[0, c], e[1, c], dt[c]
                )
            )
    else:
        for c in range(count):
            out[0, c], out[1, c], out[2, c], out[3, c] = motion.cca_scalar(
                p[0, c], p[1, c], p[2, c], p[3, c], p[4, c], p[5, c], dt[c]
            )
            out[4, c], out[5, c] = p[4, c], p[5, c]


@_jit
def _deviate(dev, row, y0, angles, count) -> None:
    """``dev[row] -= y0`` (``(m, b)``), the angle rows wrapped (:func:`wrap_residual`)."""
    for j in range(y0.shape[0]):
        for c in range(count):
            dev[row, j, c] -= y0[j, c]
    for a in angles:
        for c in range(count):
            dev[row, a, c] = wrap_residual(dev[row, a, c])


@_jit
def _moments(dev, rows, y0, weights, angles, count, shift, out_mean, half) -> None:
    """:func:`localization.compiled.ukf._moments` of each run: ``dev (>= rows, m, b)`` the
    deviations, ``y0 (m, b)`` the centre images, ``weights = (gamma, W_i, c0)``. Writes
    ``shift (m, b) = d``, ``out_mean (m, b) = y0 + d`` (angles wrapped) and the half product
    ``half (m, m, b) = H`` (the covariance is ``H + H^T`` plus the noise, :func:`_symmetric`)."""
    m = y0.shape[0]
    wi = weights[1]
    half_wi = 0.5 * wi
    half_c = 0.5 * (weights[2] - 1.0)
    for j in range(m):  # d = sum W_i D_i
        for c in range(count):
            shift[j, c] = 0.0
        for row in range(rows):
            for c in range(count):
                shift[j, c] += wi * dev[row, j, c]
        for c in range(count):
            out_mean[j, c] = y0[j, c] + shift[j, c]
    for a in angles:
        for c in range(count):
            out_mean[a, c] = wrap_angle(out_mean[a, c])
    for j in range(m):  # H = [D; d]^T diag(W_i / 2, (c0 - 1) / 2) [D; d]
        for k in range(m):
            for c in range(count):
                half[j, k, c] = 0.0
            for row in range(rows):
                for c in range(count):
                    half[j, k, c] += (half_wi * dev[row, j, c]) * dev[row, k, c]
            for c in range(count):
                half[j, k, c] = half[j, k, c] + (half_c * shift[j, c]) * shift[k, c]


@_jit
def _noise_entry(noise, start, c, j, k):
    """``noise[b, j, k]`` of run ``b = start + c``, or the shared ``noise[0, j, k]``."""
    return noise[start + c if noise.shape[0] > 1 else 0, j, k]


@_jit
def _predicted_into(half, noise, additive, start, count, mean_soa, out_mean, out_cov) -> None:
    """The runs' predicted means ``mean_soa (n, b)`` and covariances ``H + H^T (+ Q)`` of
    ``half (n, n, b)`` into rows ``start ..`` of ``out_mean (B, n)``, ``out_cov (B, n, n)``."""
    n = half.shape[0]
    for c in range(count):
        b = start + c
        for j in range(n):
            out_mean[b, j] = mean_soa[j, c]
            for k in range(j + 1):
                value = half[j, k, c] + half[k, j, c]
                if additive:
                    value = value + _noise_entry(noise, start, c, j, k)
                out_cov[b, j, k] = value
                out_cov[b, k, j] = value


@_jit
def _first_failure(status, start, count, out_mean, out_cov) -> int:
    """The first status that is not ``OK`` of the block's runs, the results of those still
    ``OK`` checked finite (else ``NOT_FINITE``); ``OK`` when none."""
    for c in range(count):
        if status[c] == OK and not (
            all_finite(out_mean[start + c]) and all_finite(out_cov[start + c])
        ):
            status[c] = NOT_FINITE
        if status[c] != OK:
            return status[c]
    return OK


@_jit
def _dt_of(args, start, count, dt) -> None:
    """``dt[c] = args[b, 0]`` of run ``b = start + c`` (or the shared row)."""
    for c in range(count):
        dt[c] = args[start + c if args.shape[0] > 1 else 0, 0]


@_jit
def _predict(model, augmented, mean, cov, args, noise, weights, angles, out_mean, out_cov):
    """The batched prediction of the built-in model ``model``, additive noise (``noise`` is
    ``Q (B or 1, n, n)``) or ``augmented`` (``noise`` a square root ``S (B or 1, q, q)``,
    ``weights`` those of dimension ``n + q``); arguments and status as the module docstring
    says. Called through :func:`predict_builtin` and :func:`noisy_predict_builtin`."""
    if not all_finite(args):
        return NOT_FINITE
    n, q = mean.shape[1], noise.shape[1]
    dim = n + q if augmented else n
    rows = 2 * dim
    size = RUN_BLOCK
    x, chol = np.empty((n, size)), np.empty((n, n, size))
    prior, half = np.empty((n, n, size)), np.empty((n, n, size))
    point, increments = np.empty((n, size)), np.zeros((q, size))
    y0, shift, mean_soa = np.empty((n, size)), np.empty((n, size)), np.empty((n, size))
    dev = np.empty((rows, n, size))
    dt = np.empty(size)
    pd = np.empty(size, dtype=np.bool_)
    status = np.empty(size, dtype=np.int64)
    gamma = weights[0]
    for start in range(0, mean.shape[0], size):
        count = min(size, mean.shape[0] - start)
        _gather(mean, cov, start, count, x, prior)
        _dt_of(args, start, count, dt)
        pd[:] = True
        _cholesky(prior, count, chol, pd)
        _images(model, augmented, x, increments, dt, count, y0)  # the centre, no noise
        for i in range(dim):
            for sign in range(2):
                row = i + sign * dim
                for j in range(n):
                    for c in range(count):
                        spread = gamma * chol[j, i, c] if i < n else 0.0
                        point[j, c] = x[j, c] + spread if sign == 0 else x[j, c] - spread
                if augmented:
                    for j in range(q):
                        for c in range(count):
                            spread = (
                                gamma * _noise_entry(noise, start, c, j, i - n) if i >= n else 0.0
                            )
                            increments[j, c] = spread if sign == 0 else -spread
                _images(model, augmented, point, increments, dt, count, dev[row])
                _deviate(dev, row, y0, angles, count)
        if augmented:
            increments[:] = 0.0  # the next block's centre
        _moments(dev, rows, y0, weights, angles, count, shift, mean_soa, half)
        _predicted_into(half, noise, not augmented, start, count, mean_soa, out_mean, out_cov)
        for c in range(count):
            status[c] = OK if pd[c] else NOT_POSITIVE_DEFINITE
        found = _first_failure(status, start, count, out_mean, out_cov)
        if found != OK:
            return found
    return OK


@_jit
def update_leading_entries(
    mean, cov, z, args, r_cov, weights, state_angles, angles, out_mean, out_cov
):
    """The batched update by the GPS or pose model (``z (B, m)`` the leading ``m`` entries of
    the state, :func:`~localization.compiled.motion.leading_entries_point`), ``r_cov (B or 1, m,
    m)``; arguments and status as :func:`localization.compiled.ukf.update_run` per run."""
    if not all_finite(args):
        return NOT_FINITE
    n, m = mean.shape[1], z.shape[1]
    size = RUN_BLOCK
    x, chol, prior = np.empty((n, size)), np.empty((n, n, size)), np.empty((n, n, size))
    z0, shift, z_pred = np.empty((m, size)), np.empty((m, size)), np.empty((m, size))
    innovation = np.empty((m, size))
    dev = np.empty((2 * n, m, size))
    s_half, s_cov, s_chol = np.empty((m, m, size)), np.empty((m, m, size)), np.empty((m, m, size))
    cross, gain_t = np.empty((n, m, size)), np.empty((m, n, size))
    mean_soa, cov_soa = np.empty((n, size)), np.empty((n, n, size))
    pd, pd_s = np.empty(size, dtype=np.bool_), np.empty(size, dtype=np.bool_)
    status = np.empty(size, dtype=np.int64)
    gamma = weights[0]
    scale = weights[1] * gamma
    for start in range(0, mean.shape[0], size):
        count = min(size, mean.shape[0] - start)
        _gather(mean, cov, start, count, x, prior)
        pd[:] = True
        _cholesky(prior, count, chol, pd)
        for j in range(m):  # Z_0 = h(x)
            for c in range(count):
                z0[j, c] = x[j, c]
        for i in range(n):  # Z_i - Z_0, h the leading entries of x +- gamma L_i
            for sign in range(2):
                row = i + sign * n
                for j in range(m):
                    for c in range(count):
                        spread = gamma * chol[j, i, c]
                        dev[row, j, c] = x[j, c] + spread if sign == 0 else x[j, c] - spread
                _deviate(dev, row, z0, angles, count)
        _moments(dev, 2 * n, z0, weights, angles, count, shift, z_pred, s_half)
        for j in range(m):  # S = H + H^T + R
            for k in range(j + 1):
                for c in range(count):
                    value = s_half[j, k, c] + s_half[k, j, c]
                    value = value + _noise_entry(r_cov, start, c, j, k)
                    s_cov[j, k, c] = value
                    s_cov[k, j, c] = value
        for i in range(n):  # Pxz = W_i gamma L (D_{1..n} - D_{n+1..2n})
            for col in range(m):
                for c in range(count):
                    cross[i, col, c] = 0.0
                for k in range(n):
                    for c in range(count):
                        cross[i, col, c] += chol[i, k, c] * (dev[k, col, c] - dev[n + k, col, c])
                for c in range(count):
                    cross[i, col, c] = scale * cross[i, col, c]
        pd_s[:] = True  # K^T = S^-1 Pxz^T (linalg.gain_from_cross, cholesky_solve)
        _cholesky(s_cov, count, s_chol, pd_s)
        for col in range(m):
            for i in range(n):
                for c in range(count):
                    gain_t[col, i, c] = cross[i, col, c]
        for i in range(n):  # column i of the right-hand side
            for r in range(m):  # L y = b
                for k in range(r):
                    for c in range(count):
                        gain_t[r, i, c] -= s_chol[r, k, c] * gain_t[k, i, c]
                for c in range(count):
                    gain_t[r, i, c] = gain_t[r, i, c] / s_chol[r, r, c]
            for r in range(m - 1, -1, -1):  # L^T x = y
                for k in range(r + 1, m):
                    for c in range(count):
                        gain_t[r, i, c] -= s_chol[k, r, c] * gain_t[k, i, c]
                for c in range(count):
                    gain_t[r, i, c] = gain_t[r, i, c] / s_chol[r, r, c]
        for col in range(m):
            for c in range(count):
                innovation[col, c] = z[start + c, col] - z_pred[col, c]
        for a in angles:
            for c in range(count):
                innovation[a, c] = wrap_angle(innovation[a, c])
        for i in range(n):  # x+ = x- + K (z - z-)
            for c in range(count):
                mean_soa[i, c] = 0.0
            for col in range(m):
                for c in range(count):
                    mean_soa[i, c] += innovation[col, c] * gain_t[col, i, c]
            for c in range(count):
                mean_soa[i, c] = x[i, c] + mean_soa[i, c]
        for a in state_angles:
            for c in range(count):
                mean_soa[a, c] = wrap_angle(mean_soa[a, c])
        for i in range(n):  # P+ = P- - Pxz K^T
            for j in range(n):
                for c in range(count):
                    cov_soa[i, j, c] = 0.0
                for col in range(m):
                    for c in range(count):
                        cov_soa[i, j, c] += cross[i, col, c] * gain_t[col, j, c]
                for c in range(count):
                    cov_soa[i, j, c] = prior[i, j, c] - cov_soa[i, j, c]
        for c in range(count):  # symmetrised (linalg.symmetrise_in_place), into the outputs
            b = start + c
            for i in range(n):
                out_mean[b, i] = mean_soa[i, c]
                out_cov[b, i, i] = cov_soa[i, i, c]
                for j in range(i):
                    value = 0.5 * (cov_soa[i, j, c] + cov_soa[j, i, c])
                    out_cov[b, i, j] = value
                    out_cov[b, j, i] = value
        for c in range(count):
            if not all_finite(z[start + c]):
                status[c] = NOT_FINITE
            elif not (pd[c] and pd_s[c]):  # P, then S
                status[c] = NOT_POSITIVE_DEFINITE
            else:
                status[c] = OK
        found = _first_failure(status, start, count, out_mean, out_cov)
        if found != OK:
            return found
    return OK


@_jit
def predict_builtin(model, mean, cov, args, q_cov, weights, angles, out_mean, out_cov) -> int:
    """The batched prediction of the built-in model number ``model``, additive noise
    ``q_cov (B or 1, n, n)`` (:func:`_predict`)."""
    return _predict(model, False, mean, cov, args, q_cov, weights, angles, out_mean, out_cov)


@_jit
def noisy_predict_builtin(model, mean, cov, args, root, weights, angles, out_mean, out_cov) -> int:
    """The batched prediction of the built-in model number ``model``, augmented noise with the
    square root ``root (B or 1, q, q)`` (:func:`_predict`)."""
    return _predict(model, True, mean, cov, args, root, weights, angles, out_mean, out_cov)
