"""The motion models of :mod:`localization.motion_models` for one state (numba): THE formulas.

Each model of paper 001 (CV, CTRV, CTRA, CCA) is written once, here, as a scalar function of
the state's entries (``*_scalar``, inlined: the one source per formula), wrapped by a per-point kernel,
and everything else is generated from it:

- ``*_point(x (n,), args (1,) = (dt_s,), out (n,))``: the transition of one state, written
  into ``out``; ``*_noisy_point(x, e (2,), args, out)`` the same with the noise increments
  ``e`` of the augmented UKF (``*_noisy_scalar``); ``*_jacobian_point(x, args, out (n, n))``
  its Jacobian; :func:`trig_moments_point` the trigonometric moments they share.
- The batched numpy API of :mod:`localization.motion_models` (``cv_transition(x (..., n),
  dt_s)`` and the rest) runs these kernels over the rows of a batch (:func:`transition_rows`,
  :func:`jacobian_rows`, :func:`noisy_transition_rows`, :func:`trig_moment_rows`): the batched
  result of a state is its per-point result, bit for bit.
- The compiled UKF and EKF steps (:mod:`localization.compiled.ukf`,
  :mod:`localization.compiled.ekf`, :mod:`localization.compiled.lean`) inline them per sigma
  point or per state.

The maths, the state layouts and the paper errata are documented in
:mod:`localization.motion_models`; the independent checks (finite differences of the
Jacobians, Gauss-Legendre quadrature of the continuous CCA model, closed-form limits and
quadrature of the moments) are the tests of ``tests/localization/test_motion_models.py``.

Built-in kernels are numbered (``CV`` 0, ``CTRV`` 1, ``CTRA`` 2, ``CCA`` 3: :data:`MODEL_NUMBERS`);
the row loops and the compiled entries switch on that number, so one cached compilation
serves the four models.
"""

from __future__ import annotations

import math

import numba

from localization.compiled.linalg import wrap_angle

#: Below this ``|u|`` the moments ``M_1^s`` and ``M_2^s`` use their Taylor series (their
#: closed forms cancel to ``u^2``); above it the closed forms lose at most 1e-13 relative.
SERIES_BELOW = 0.1


def _sin_moment_series(order: int, terms: int = 5) -> tuple[float, ...]:
    """Taylor coefficients of ``M_k^s(u) / u`` in powers of ``u^2`` (truncation < 1e-18 at 0.1)."""
    return tuple(
        (-1.0) ** j / (math.factorial(2 * j + 1) * (2 * j + order + 2)) for j in range(terms)
    )


_M1S_OVER_U = _sin_moment_series(1)  # 1/3 - u^2/30 + ...
_M2S_OVER_U = _sin_moment_series(2)  # 1/4 - u^2/36 + ...

#: The built-in models by name, as numbered in the row loops and the compiled entries.
MODEL_NUMBERS = {"CV": 0, "CTRV": 1, "CTRA": 2, "CCA": 3}


@numba.njit(cache=True)
def trig_moments_point(u):
    """``(M0c, M1c, M2c, M0s, M1s, M2s)`` of one angle ``u`` (rad): the trigonometric moments
    ``M_k^c(u) = int_0^1 t^k cos(u t) dt`` and ``M_k^s(u) = int_0^1 t^k sin(u t) dt``, ``k <= 2``.

    ``dM_k^c/du = -M_(k+1)^s`` and ``dM_k^s/du = M_(k+1)^c``. Safe at ``u = 0`` (no division by
    a small number), written without cancellation where a half-angle form exists::

        M_0^c = sinc(u),  M_0^s = (1 - cos u)/u = sin(u/2) sinc(u/2)
        M_1^c = (sin u - M_0^s)/u = sinc(u) - sinc(u/2)^2 / 2
        M_1^s = (M_0^c - cos u)/u          (Taylor series below |u| = SERIES_BELOW)
        M_2^c = (sin u - 2 M_1^s)/u = sinc(u) - 2 M_1^s/u
        M_2^s = (2 M_1^c - cos u)/u        (Taylor series below |u| = SERIES_BELOW)

    with ``sinc(z) = sin(z)/z`` (integration by parts gives the recurrences); ``u = 0`` is
    replaced by ``1e-300`` in the sincs, where ``sin(z)/z`` is exactly 1.
    """
    u_nz = 1e-300 if u == 0.0 else u
    half = 0.5 * u_nz
    sin_h = math.sin(half)
    sinc_u = math.sin(u_nz) / u_nz
    sinc_h = sin_h / half
    u2 = u * u
    cos_u = math.cos(u)
    small = abs(u) < SERIES_BELOW
    if small:
        m1s_over_u = _M1S_OVER_U[4]
        m2s_over_u = _M2S_OVER_U[4]
        for k in range(3, -1, -1):
            m1s_over_u = m1s_over_u * u2 + _M1S_OVER_U[k]
            m2s_over_u = m2s_over_u * u2 + _M2S_OVER_U[k]
    else:
        m1s_over_u = (sinc_u - cos_u) / u2
    mc1 = sinc_u - 0.5 * sinc_h * sinc_h
    if not small:
        m2s_over_u = (2.0 * mc1 - cos_u) / u2
    return sinc_u, mc1, sinc_u - 2.0 * m1s_over_u, sin_h * sinc_h, u * m1s_over_u, u * m2s_over_u


@numba.njit(cache=True)
def _identity_point(out) -> None:
    """``out (m, n) = [I 0]`` (``m <= n``)."""
    out[:] = 0.0
    for j in range(out.shape[0]):
        out[j, j] = 1.0


@numba.njit(cache=True, inline="always")
def arc_scalar(px, py, theta, length, turn):
    """The pose ``(x, y, theta)`` after a circular arc from ``(px, py)`` at heading ``theta``
    (rad) of the signed ``length`` (m) turning by ``turn`` (rad): THE arc formula.

    Its displacement ``length (M_0^c, M_0^s)(turn)`` in the frame of ``theta`` is the chord,
    ``(M_0^c, M_0^s)(u) = sinc(u/2) (cos, sin)(u/2)``, so in the world frame it is
    ``length sinc(turn/2) (cos, sin)(theta + turn/2)``, ``sinc(0) = 1``: no turn gives the
    straight line bit for bit. (Until session 24 ``sinc(h)`` was ``sin(a)/a`` with ``a =
    hypot(h, 1e-300)``, without a branch; ``a`` is ``|h|`` there unless ``|h|`` is below about
    1e-290, where both ratios are exactly 1, so the two agree bit for bit, the branch without
    the ``hypot`` call.) The heading is wrapped to ``[-pi, pi)``.
    """
    half = 0.5 * turn
    chord = (math.sin(half) / half if half != 0.0 else 1.0) * length
    direction = theta + half
    return (
        px + chord * math.cos(direction),
        py + chord * math.sin(direction),
        wrap_angle(theta + turn),
    )


@numba.njit(cache=True, inline="always")
def cv_scalar(px, py, vx, vy, dt):
    """CV, paper 001 eq. 3: the position ``(x + vx dt, y + vy dt)`` (m) over ``dt`` (s)."""
    return px + vx * dt, py + vy * dt


@numba.njit(cache=True, inline="always")
def ctrv_scalar(px, py, theta, v, omega, dt):
    """CTRV, paper 001 eq. 5 (corrected): the pose ``(x, y, theta)`` after an arc of length
    ``v dt`` turning by ``omega dt`` (:func:`arc_scalar`); ``v`` and ``omega`` are constant."""
    return arc_scalar(px, py, theta, v * dt, omega * dt)


@numba.njit(cache=True, inline="always")
def ctra_scalar(px, py, theta, v, accel, omega, dt):
    """CTRA, paper 001 eq. 7-9: ``(x, y, theta, v)`` over ``dt`` (s); ``a`` and ``omega`` constant.

    The displacement in the frame of the initial heading (eq. 5, 8-9 rewritten) is
    ``int_0^T (v + a t) (cos, sin)(omega t) dt = v T (M0c, M0s) + a T^2 (M1c, M1s)`` of the
    turned angle ``u = omega T`` (:func:`trig_moments_point`).
    """
    u = omega * dt
    mc0, mc1, _, ms0, ms1, _ = trig_moments_point(u)
    forward = v * dt * mc0 + accel * (dt * dt) * mc1
    left = v * dt * ms0 + accel * (dt * dt) * ms1
    c, s = math.cos(theta), math.sin(theta)
    return (
        px + (c * forward - s * left),
        py + (s * forward + c * left),
        wrap_angle(theta + u),
        v + accel * dt,
    )


@numba.njit(cache=True, inline="always")
def cca_scalar(px, py, theta, v, a, c, dt):
    """CCA, the re-derived closed form of paper 001 eq. 17: ``(x, y, theta, v)`` over ``dt`` (s).

    With ``s = v T + a T^2 / 2``: a circular arc of length ``s`` turning by ``c s``
    (:func:`arc_scalar`), ``v += a T``; ``a`` and ``c`` are constant.
    """
    s = v * dt + 0.5 * a * (dt * dt)
    px1, py1, theta1 = arc_scalar(px, py, theta, s, c * s)
    return px1, py1, theta1, v + a * dt


@numba.njit(cache=True)
def cv_point(x, args, out) -> None:
    """CV (:func:`cv_scalar`); ``x (4,) = (x, y, vx, vy)``, ``args = (dt_s,)``, into ``out (4,)``."""
    out[:] = x
    out[0], out[1] = cv_scalar(x[0], x[1], x[2], x[3], args[0])


@numba.njit(cache=True)
def ctrv_point(x, args, out) -> None:
    """CTRV (:func:`ctrv_scalar`); ``x (5,) = (x, y, theta, v, omega)``, ``args = (dt_s,)``,
    into ``out (5,)``."""
    out[:] = x
    out[0], out[1], out[2] = ctrv_scalar(x[0], x[1], x[2], x[3], x[4], args[0])


@numba.njit(cache=True)
def ctra_point(x, args, out) -> None:
    """CTRA (:func:`ctra_scalar`); ``x (6,) = (x, y, theta, v, a, omega)``, ``args = (dt_s,)``,
    into ``out (6,)``."""
    out[:] = x
    out[0], out[1], out[2], out[3] = ctra_scalar(x[0], x[1], x[2], x[3], x[4], x[5], args[0])


@numba.njit(cache=True)
def cca_point(x, args, out) -> None:
    """CCA (:func:`cca_scalar`); ``x (6,) = (x, y, theta, v, a, c)``, ``args = (dt_s,)``,
    into ``out (6,)``."""
    out[:] = x
    out[0], out[1], out[2], out[3] = cca_scalar(x[0], x[1], x[2], x[3], x[4], x[5], args[0])


# The augmented UKF's noise increments ``(e_0, e_1)`` ramp two entries (the driven ones) over the
# step (:meth:`localization.motion_models.MotionModel.transition_with_noise`): half of each is
# added to the state before the transition (at mid-step) and half to its image after it.


@numba.njit(cache=True, inline="always")
def cv_noisy_scalar(px, py, vx, vy, e_vx, e_vy, dt):
    """CV (:func:`cv_scalar`) with the increments ``(e_vx, e_vy)`` of ``(vx, vy)``: the new
    ``(x, y, vx, vy)``."""
    vx_mid, vy_mid = vx + 0.5 * e_vx, vy + 0.5 * e_vy
    px1, py1 = cv_scalar(px, py, vx_mid, vy_mid, dt)
    return px1, py1, vx_mid + 0.5 * e_vx, vy_mid + 0.5 * e_vy


@numba.njit(cache=True, inline="always")
def ctrv_noisy_scalar(px, py, theta, v, omega, e_v, e_omega, dt):
    """CTRV (:func:`ctrv_scalar`) with the increments ``(e_v, e_omega)`` of ``(v, omega)``: the
    new ``(x, y, theta, v, omega)``."""
    v_mid, omega_mid = v + 0.5 * e_v, omega + 0.5 * e_omega
    px1, py1, theta1 = ctrv_scalar(px, py, theta, v_mid, omega_mid, dt)
    return px1, py1, theta1, v_mid + 0.5 * e_v, omega_mid + 0.5 * e_omega


@numba.njit(cache=True, inline="always")
def ctra_noisy_scalar(px, py, theta, v, accel, omega, e_accel, e_omega, dt):
    """CTRA (:func:`ctra_scalar`) with the increments ``(e_accel, e_omega)`` of ``(a, omega)``:
    the new ``(x, y, theta, v, a, omega)``."""
    accel_mid, omega_mid = accel + 0.5 * e_accel, omega + 0.5 * e_omega
    px1, py1, theta1, v1 = ctra_scalar(px, py, theta, v, accel_mid, omega_mid, dt)
    return px1, py1, theta1, v1, accel_mid + 0.5 * e_accel, omega_mid + 0.5 * e_omega


@numba.njit(cache=True, inline="always")
def cca_noisy_scalar(px, py, theta, v, a, c, e_a, e_c, dt):
    """CCA (:func:`cca_scalar`) with the increments ``(e_a, e_c)`` of ``(a, c)``: the new
    ``(x, y, theta, v, a, c)``."""
    a_mid, c_mid = a + 0.5 * e_a, c + 0.5 * e_c
    px1, py1, theta1, v1 = cca_scalar(px, py, theta, v, a_mid, c_mid, dt)
    return px1, py1, theta1, v1, a_mid + 0.5 * e_a, c_mid + 0.5 * e_c


@numba.njit(cache=True)
def cv_noisy_point(x, noise, args, out) -> None:
    """CV with the increments ``noise (2,)`` of ``(vx, vy)`` (augmented noise,
    :func:`cv_noisy_scalar`), into ``out (4,)``."""
    out[0], out[1], out[2], out[3] = cv_noisy_scalar(
        x[0], x[1], x[2], x[3], noise[0], noise[1], args[0]
    )


@numba.njit(cache=True)
def ctrv_noisy_point(x, noise, args, out) -> None:
    """CTRV with the increments ``noise (2,)`` of ``(v, omega)`` (augmented noise,
    :func:`ctrv_noisy_scalar`), into ``out (5,)``."""
    out[0], out[1], out[2], out[3], out[4] = ctrv_noisy_scalar(
        x[0], x[1], x[2], x[3], x[4], noise[0], noise[1], args[0]
    )


@numba.njit(cache=True)
def ctra_noisy_point(x, noise, args, out) -> None:
    """CTRA with the increments ``noise (2,)`` of ``(a, omega)`` (augmented noise,
    :func:`ctra_noisy_scalar`), into ``out (6,)``."""
    out[0], out[1], out[2], out[3], out[4], out[5] = ctra_noisy_scalar(
        x[0], x[1], x[2], x[3], x[4], x[5], noise[0], noise[1], args[0]
    )


@numba.njit(cache=True)
def cca_noisy_point(x, noise, args, out) -> None:
    """CCA with the increments ``noise (2,)`` of ``(a, c)`` (augmented noise,
    :func:`cca_noisy_scalar`), into ``out (6,)``."""
    out[0], out[1], out[2], out[3], out[4], out[5] = cca_noisy_scalar(
        x[0], x[1], x[2], x[3], x[4], x[5], noise[0], noise[1], args[0]
    )


@numba.njit(cache=True)
def leading_entries_point(x, args, out) -> None:
    """``out (m,) = x[:m]``: the GPS position (``m = 2``) or the pose (``m = 3``) of
    :mod:`localization.motion_models`."""
    for j in range(out.shape[0]):
        out[j] = x[j]


@numba.njit(cache=True)
def leading_entries_jacobian_point(x, args, out) -> None:
    """``out (m, n) = [I 0]``: the Jacobian of :func:`leading_entries_point`."""
    _identity_point(out)


# Jacobian kernels ``F(x (n,), args = (dt_s,), out (n, n))``, every entry of ``out`` written.


@numba.njit(cache=True)
def cv_jacobian_point(x, args, out) -> None:
    """Jacobian ``(4, 4)`` of :func:`cv_point`, into ``out``."""
    dt = args[0]
    _identity_point(out)
    out[0, 2] = dt
    out[1, 3] = dt


@numba.njit(cache=True)
def _ctra_like_jacobian_point(x, dt, accel, omega, i_omega, out) -> None:
    """Jacobian of CTRV (``i_omega = 4``; ``accel`` NaN and unused) or CTRA (``i_omega = 5``,
    the acceleration at index 4) into ``out (n, n)``: ``d/domega`` of ``(M_k^c, M_k^s)(omega T)``
    is ``T (-M_(k+1)^s, M_(k+1)^c)``, hence the moments to order 2."""
    theta, v = x[2], x[3]
    has_accel = i_omega == 5
    mc0, mc1, mc2, ms0, ms1, ms2 = trig_moments_point(omega * dt)
    forward = v * dt * mc0
    left = v * dt * ms0
    if has_accel:
        forward = forward + accel * (dt * dt) * mc1
        left = left + accel * (dt * dt) * ms1
    c, s = math.cos(theta), math.sin(theta)
    _identity_point(out)
    out[0, 2] = -(s * forward + c * left)
    out[1, 2] = c * forward - s * left
    out[0, 3] = c * (dt * mc0) - s * (dt * ms0)
    out[1, 3] = s * (dt * mc0) + c * (dt * ms0)
    d_forward = -dt * dt * v * ms1
    d_left = dt * dt * v * mc1
    if has_accel:
        d_forward = d_forward - dt**3 * accel * ms2
        d_left = d_left + dt**3 * accel * mc2
        out[0, 4] = c * ((dt * dt) * mc1) - s * ((dt * dt) * ms1)
        out[1, 4] = s * ((dt * dt) * mc1) + c * ((dt * dt) * ms1)
        out[3, 4] = dt
    out[0, i_omega] = c * d_forward - s * d_left
    out[1, i_omega] = s * d_forward + c * d_left
    out[2, i_omega] = dt


@numba.njit(cache=True)
def ctrv_jacobian_point(x, args, out) -> None:
    """Jacobian ``(5, 5)`` of :func:`ctrv_point`, into ``out``."""
    _ctra_like_jacobian_point(x, args[0], math.nan, x[4], 4, out)


@numba.njit(cache=True)
def ctra_jacobian_point(x, args, out) -> None:
    """Jacobian ``(6, 6)`` of :func:`ctra_point`, into ``out``."""
    _ctra_like_jacobian_point(x, args[0], x[4], x[5], 5, out)


@numba.njit(cache=True)
def cca_jacobian_point(x, args, out) -> None:
    """Jacobian ``(6, 6)`` of :func:`cca_point`, into ``out``; ``d(local)/ds = (cos u, sin u)``
    is the tangent at the end of the arc."""
    dt = args[0]
    theta, v, a, c = x[2], x[3], x[4], x[5]
    s = v * dt + 0.5 * a * (dt * dt)
    u = c * s
    mc0, mc1, _, ms0, ms1, _ = trig_moments_point(u)
    cos_t, sin_t = math.cos(theta), math.sin(theta)
    _identity_point(out)
    forward, left = s * mc0, s * ms0
    out[0, 2] = -(sin_t * forward + cos_t * left)
    out[1, 2] = cos_t * forward - sin_t * left
    cos_u, sin_u = math.cos(u), math.sin(u)
    tx = cos_t * cos_u - sin_t * sin_u
    ty = sin_t * cos_u + cos_t * sin_u
    out[0, 3] = tx * dt
    out[1, 3] = ty * dt
    out[0, 4] = tx * 0.5 * (dt * dt)
    out[1, 4] = ty * 0.5 * (dt * dt)
    d_forward, d_left = -s * s * ms1, s * s * mc1
    out[0, 5] = cos_t * d_forward - sin_t * d_left
    out[1, 5] = sin_t * d_forward + cos_t * d_left
    out[2, 3] = c * dt
    out[2, 4] = 0.5 * c * (dt * dt)
    out[2, 5] = s
    out[3, 4] = dt


# ------------------------------------------------------------------- the batched API's loops
# One loop per kind of kernel, switching on the model number (MODEL_NUMBERS) inside: one
# cached compilation for the four models. ``x (N, n)``, ``dt (N,)``: row ``i`` is
# ``kernel(x[i], dt[i:i + 1], out[i])``.


@numba.njit(cache=True)
def transition_rows(model, x, dt, out) -> None:
    """``out (N, n)``: the transition of each row of ``x (N, n)`` over ``dt (N,)`` seconds."""
    for i in range(x.shape[0]):
        args = dt[i : i + 1]
        if model == 0:
            cv_point(x[i], args, out[i])
        elif model == 1:
            ctrv_point(x[i], args, out[i])
        elif model == 2:
            ctra_point(x[i], args, out[i])
        else:
            cca_point(x[i], args, out[i])


@numba.njit(cache=True)
def noisy_transition_rows(model, x, noise, dt, out) -> None:
    """``out (N, n)``: the noise-augmented transition of each row of ``x (N, n)`` with the
    increments ``noise (N, 2)`` over ``dt (N,)`` seconds."""
    for i in range(x.shape[0]):
        args = dt[i : i + 1]
        if model == 0:
            cv_noisy_point(x[i], noise[i], args, out[i])
        elif model == 1:
            ctrv_noisy_point(x[i], noise[i], args, out[i])
        elif model == 2:
            ctra_noisy_point(x[i], noise[i], args, out[i])
        else:
            cca_noisy_point(x[i], noise[i], args, out[i])


@numba.njit(cache=True)
def jacobian_rows(model, x, dt, out) -> None:
    """``out (N, n, n)``: the Jacobian of the transition at each row of ``x (N, n)``."""
    for i in range(x.shape[0]):
        args = dt[i : i + 1]
        if model == 0:
            cv_jacobian_point(x[i], args, out[i])
        elif model == 1:
            ctrv_jacobian_point(x[i], args, out[i])
        elif model == 2:
            ctra_jacobian_point(x[i], args, out[i])
        else:
            cca_jacobian_point(x[i], args, out[i])


@numba.njit(cache=True)
def trig_moment_rows(u, out) -> None:
    """``out (N, 6)``: :func:`trig_moments_point` of each angle of ``u (N,)``."""
    for i in range(u.shape[0]):
        mc0, mc1, mc2, ms0, ms1, ms2 = trig_moments_point(u[i])
        out[i, 0], out[i, 1], out[i, 2] = mc0, mc1, mc2
        out[i, 3], out[i, 4], out[i, 5] = ms0, ms1, ms2
