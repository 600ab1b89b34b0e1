"""The compiled dead-reckoning step (numba): a whole stretch of samples in one call.

:class:`~localization.dead_reckoning.DeadReckoning` calls :func:`run_steps` once per
``run()`` stretch; the kernel loops over the samples ``start..stop-1`` and, inside each
sample, over the runs of the batch, and writes the history rows in place. It is the same
filter as the generic filter classes (:mod:`localization.ukf`, :mod:`localization.iukf`,
:mod:`localization.ekf`) on the model of :mod:`localization.dead_reckoning` (the reference
it is tested against, ``tests/localization/test_dead_reckoning.py``):

- prediction, unscented (UKF, IUKF; paper 001 eq. 25-27): sigma points
  ``X_0 = x``, ``X_i = x + gamma L_i``, ``X_{n+i} = x - gamma L_i`` (``L`` the lower Cholesky
  factor of ``P``), images ``Y_i = f(X_i)``, and the moments about the centre image as in
  :func:`localization.sigma_points.unscented_moments`: ``D_i = Y_i - Y_0``,
  ``d = W sum D_i``, ``x- = Y_0 + d``, ``P- = W sum D_i D_i^T + (c0 - 1) d d^T + Q``;
- prediction, linearised (EKF, IEKF): ``x- = f(x)``, ``P- = F P F^T + Q``;
- update, closed form for the linear ``h(s) = H(k) s`` (the unscented update equals it, and
  the iterated ones converge at their first iteration; module docstring of
  :mod:`localization.dead_reckoning`): ``S = H P- H^T + R``, ``K^T = S^-1 H P-`` (Cholesky
  solve), ``x+ = x- + K (z - H x-)``, ``P+ = P- - P- H^T K^T`` (``ExtendedKalmanFilter``
  takes the Joseph form, equal in exact arithmetic); and the normalised innovation squared
  ``NIS = nu^T S^-1 nu = |C^-1 nu|^2`` of the innovation ``nu = z - H x-`` (``C C^T = S``,
  one forward substitution; Bar-Shalom, Li and Kirubarajan 2001, section 5.4.2).

Covariances are built from their lower triangle and mirrored, so they stay exactly
symmetric. The heading is kept unwrapped in the carried mean (the model is periodic in it)
and wrapped into the history. With ``wrap_offsets`` the heading offsets ``D_i`` are wrapped
to ``[-pi, pi]`` as the generic filter does; without it (the tiny scaled points) the caller
checks ``gamma sigma_theta < pi``.

Shapes (``N`` samples, ``B`` runs, ``n = 8`` states): per-sample inputs have a batch axis of
``B`` (per-run data) or 1 (shared data). All arrays float64, C-contiguous: one compiled
signature.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from localization.compiled.linalg import (
    all_finite,
    cholesky_lower,
    kalman_gain_t,
    wrap_angle,
    wrap_residual,
)

X, Y, THETA, V, OMEGA, B_GYRO, B_ACCEL, D_WHEEL = range(8)
N_STATES = 8
N_MEASUREMENTS = 3  # (v_enc, omega_enc, gyro)


@numba.njit(cache=True)
def transition(state, accel_m_s2, dt_s, out) -> None:
    """``out (8,) = f(state (8,))`` over ``dt_s``: the unicycle with the mid-step heading
    ``theta + dt omega / 2``, the forward accelerometer ``accel_m_s2`` less its bias as the
    input of ``v`` (the model of :mod:`localization.dead_reckoning`; its batched
    :func:`localization.dead_reckoning.transition` runs this per state)."""
    for i in range(N_STATES):
        out[i] = state[i]
    theta, v, omega = state[THETA], state[V], state[OMEGA]
    heading = theta + 0.5 * dt_s * omega
    out[X] += dt_s * v * math.cos(heading)
    out[Y] += dt_s * v * math.sin(heading)
    out[THETA] += dt_s * omega
    out[V] += dt_s * (accel_m_s2 - state[B_ACCEL])


@numba.njit(cache=True)
def _unscented_predict(
    mean,
    cov,
    accel_m_s2,
    dt_s,
    gamma,
    weight,
    c0,
    wrap_offsets,
    q_cov,
    chol,
    point,
    image,
    dev,
    shift,
) -> bool:
    """``mean (8,)``, ``cov (8, 8)`` replaced by the unscented prediction (paper 001 eq. 25-27).

    ``weight`` is ``W_i = 1 / (2 gamma^2)``, ``c0 = Wc_0 - Wm_0``; ``chol (8, 8)``, ``point``,
    ``image``, ``shift (8,)`` and ``dev (16, 8)`` are work buffers. Returns ``False`` when
    ``cov`` is not positive definite (then nothing is changed).
    """
    n = N_STATES
    if not cholesky_lower(cov, chol):
        return False
    transition(mean, accel_m_s2, dt_s, shift)  # Y_0, kept in shift until d is known
    for i in range(n):  # X_{1+i} = x + gamma L_i, X_{n+1+i} = x - gamma L_i
        for half in range(2):
            row, sign = half * n + i, 1.0 - 2.0 * half
            for j in range(n):
                point[j] = mean[j] + sign * (gamma * chol[j, i])
            transition(point, accel_m_s2, dt_s, image)
            for j in range(n):
                dev[row, j] = image[j] - shift[j]  # D_i = Y_i - Y_0
            if wrap_offsets:
                dev[row, THETA] = wrap_residual(dev[row, THETA])
    for j in range(n):  # x- = Y_0 + d, d = W sum D_i
        total = 0.0
        for row in range(2 * n):
            total += dev[row, j]
        mean[j] = shift[j]
        shift[j] = weight * total
        mean[j] += shift[j]
    for j in range(n):  # P- = W sum D_i D_i^T + (c0 - 1) d d^T + Q, lower triangle mirrored
        for col in range(j + 1):
            total = 0.0
            for row in range(2 * n):
                total += dev[row, j] * dev[row, col]
            value = weight * total + (c0 - 1.0) * shift[j] * shift[col] + q_cov[j, col]
            cov[j, col] = value
            cov[col, j] = value
    return True


@numba.njit(cache=True)
def transition_jacobian(state, dt_s, jac) -> None:
    """``jac (8, 8) = df/ds`` of :func:`transition` at ``state (8,)`` (independent of the
    accelerometer input): the linear part ``A`` (``theta += dt omega``, ``v -= dt b_accel``)
    and the motion of ``x, y``."""
    n = N_STATES
    theta, v, omega = state[THETA], state[V], state[OMEGA]
    heading = theta + 0.5 * dt_s * omega
    cos, sin = dt_s * math.cos(heading), dt_s * math.sin(heading)
    for i in range(n):
        for j in range(n):
            jac[i, j] = 1.0 if i == j else 0.0
    jac[THETA, OMEGA] = dt_s
    jac[V, B_ACCEL] = -dt_s
    jac[X, THETA] = -v * sin
    jac[X, V] = cos
    jac[X, OMEGA] = -0.5 * dt_s * v * sin
    jac[Y, THETA] = v * cos
    jac[Y, V] = sin
    jac[Y, OMEGA] = 0.5 * dt_s * v * cos


@numba.njit(cache=True)
def transition_rows(states, accel_m_s2, dt_s, out) -> None:
    """``out (N, 8)``: :func:`transition` of each row of ``states (N, 8)`` with ``accel_m_s2 (N,)``."""
    for i in range(states.shape[0]):
        transition(states[i], accel_m_s2[i], dt_s, out[i])


@numba.njit(cache=True)
def jacobian_rows(states, dt_s, out) -> None:
    """``out (N, 8, 8)``: :func:`transition_jacobian` at each row of ``states (N, 8)``."""
    for i in range(states.shape[0]):
        transition_jacobian(states[i], dt_s, out[i])


@numba.njit(cache=True)
def _linearised_predict(mean, cov, accel_m_s2, dt_s, q_cov, jac, product, image) -> None:
    """``mean (8,)``, ``cov (8, 8)`` replaced by ``f(x)`` and ``F P F^T + Q``; ``jac``,
    ``product (8, 8)`` and ``image (8,)`` are work buffers."""
    n = N_STATES
    transition_jacobian(mean, dt_s, jac)
    transition(mean, accel_m_s2, dt_s, image)
    for i in range(n):
        mean[i] = image[i]
    for i in range(n):  # F P
        for j in range(n):
            total = 0.0
            for m in range(n):
                total += jac[i, m] * cov[m, j]
            product[i, j] = total
    for i in range(n):  # (F P) F^T + Q, lower triangle mirrored
        for j in range(i + 1):
            total = 0.0
            for m in range(n):
                total += product[i, m] * jac[j, m]
            value = total + q_cov[i, j]
            cov[i, j] = value
            cov[j, i] = value


@numba.njit(cache=True)
def _linear_update(
    mean, cov, z, r_cov, wheel_base_m, speed_correction, h, cross, s_cov, s_chol, gain_t, innovation
) -> float:
    """The closed-form update of ``mean (8,)``, ``cov (8, 8)`` by ``z (3,)``; returns the NIS
    of the innovation, or ``-1.0`` when ``S`` is not positive definite (then nothing is
    changed).

    ``H(k)`` as :func:`localization.reference.dead_reckoning.measurement_matrix` builds it, with the
    regressor ``(omega, v)`` = the predicted ``omega`` and the predicted ``v`` less
    ``speed_correction`` (the previous update's correction of ``v``). Work buffers:
    ``h (3, 8)``, ``cross (8, 3)``, ``s_cov``, ``s_chol (3, 3)``, ``gain_t (3, 8)``, ``innovation (3,)``.
    """
    n, m = N_STATES, N_MEASUREMENTS
    h[:, :] = 0.0
    h[0, V] = 1.0
    h[0, D_WHEEL] = -0.25 * wheel_base_m * mean[OMEGA]
    h[1, OMEGA] = 1.0
    h[1, D_WHEEL] = -(mean[V] - speed_correction) / wheel_base_m
    h[2, OMEGA] = 1.0
    h[2, B_GYRO] = 1.0
    if not kalman_gain_t(cov, h, r_cov, cross, s_cov, s_chol, gain_t):  # K^T = S^-1 (P H^T)^T
        return -1.0
    for r in range(m):  # z - H x-
        total = 0.0
        for j in range(n):
            total += h[r, j] * mean[j]
        innovation[r] = z[r] - total
    # NIS = |w|^2 with C w = nu, C = s_chol the lower Cholesky factor of S (m = 3 unrolled)
    w0 = innovation[0] / s_chol[0, 0]
    w1 = (innovation[1] - s_chol[1, 0] * w0) / s_chol[1, 1]
    w2 = (innovation[2] - s_chol[2, 0] * w0 - s_chol[2, 1] * w1) / s_chol[2, 2]
    nis = w0 * w0 + w1 * w1 + w2 * w2
    for i in range(n):  # x+ = x- + K (z - H x-)
        total = 0.0
        for r in range(m):
            total += innovation[r] * gain_t[r, i]
        mean[i] += total
    for i in range(n):  # P+ = P- - P H^T K^T, lower triangle mirrored
        for j in range(i + 1):
            total = 0.0
            for r in range(m):
                total += cross[i, r] * gain_t[r, j]
            value = cov[i, j] - total
            cov[i, j] = value
            cov[j, i] = value
    return nis


@numba.njit(cache=True)
def run_steps(
    mean,
    cov,
    speed_correction,
    start,
    stop,
    accel_m_s2,
    z,
    q_cov,
    r_cov,
    dt_s,
    wheel_base_m,
    unscented,
    gamma,
    weight,
    c0,
    wrap_offsets,
    mean_hist,
    cov_hist,
    nis_hist,
) -> int:
    """Samples ``start..stop-1`` of every run; returns ``-1``, or the sample where a covariance
    to factorise (``P`` or ``S``) is not positive definite or the updated mean is not finite
    (the state then holds a mix of samples: discard it).

    Args:
        mean: ``(B, 8)`` the belief at ``start - 1`` (heading unwrapped), updated in place.
        cov: ``(B, 8, 8)``, updated in place.
        speed_correction: ``(B,)`` the last update's correction of ``v``, m/s, updated in place.
        accel_m_s2: ``(N, B or 1)`` forward accelerometer input of each step.
        z: ``(N, B or 1, 3)`` measurements ``(v_enc_m_s, omega_enc_rad_s, gyro_rad_s)``.
        q_cov: ``(8, 8)`` process noise; r_cov: ``(3, 3)`` measurement noise.
        dt_s: sample period; wheel_base_m: ``L``.
        unscented: unscented prediction (else linearised); gamma, weight (``W_i``), c0 and
            wrap_offsets: the sigma points (unused when not ``unscented``).
        mean_hist: ``(N, B, 8)``, rows ``start..stop-1`` written (heading wrapped).
        cov_hist: ``(N, B, c, c)``, the leading ``c x c`` block of each covariance.
        nis_hist: ``(N, B)``, the NIS of each update (3 degrees of freedom), rows written.
    """
    n = N_STATES
    batch = mean.shape[0]
    recorded = cov_hist.shape[-1]
    chol = np.empty((n, n))
    product = np.empty((n, n))
    dev = np.empty((2 * n, n))
    point, image, shift, innovation = (
        np.empty(n),
        np.empty(n),
        np.empty(n),
        np.empty(N_MEASUREMENTS),
    )
    h, gain_t, cross = (
        np.empty((N_MEASUREMENTS, n)),
        np.empty((N_MEASUREMENTS, n)),
        np.empty((n, N_MEASUREMENTS)),
    )
    s_cov, s_chol = (
        np.empty((N_MEASUREMENTS, N_MEASUREMENTS)),
        np.empty((N_MEASUREMENTS, N_MEASUREMENTS)),
    )
    shared_accel, shared_z = accel_m_s2.shape[1] == 1, z.shape[1] == 1
    for k in range(start, stop):
        for b in range(batch):
            x, p = mean[b], cov[b]
            accel = accel_m_s2[k, 0 if shared_accel else b]
            if unscented:
                if not _unscented_predict(
                    x,
                    p,
                    accel,
                    dt_s,
                    gamma,
                    weight,
                    c0,
                    wrap_offsets,
                    q_cov,
                    chol,
                    point,
                    image,
                    dev,
                    shift,
                ):
                    return k
            else:
                _linearised_predict(x, p, accel, dt_s, q_cov, chol, product, image)
            predicted_v = x[V]
            nis = _linear_update(
                x,
                p,
                z[k, 0 if shared_z else b],
                r_cov,
                wheel_base_m,
                speed_correction[b],
                h,
                cross,
                s_cov,
                s_chol,
                gain_t,
                innovation,
            )
            if nis < 0.0 or not all_finite(x):
                return k
            nis_hist[k, b] = nis
            speed_correction[b] = x[V] - predicted_v
            for i in range(n):
                mean_hist[k, b, i] = x[i]
            mean_hist[k, b, THETA] = wrap_angle(x[THETA])
            for i in range(recorded):
                for j in range(recorded):
                    cov_hist[k, b, i, j] = p[i, j]
    return -1
