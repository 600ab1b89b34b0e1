"""Vehicle motion models of paper 001 (section II): CV, CTRV, CTRA and CCA.

Every model is a batched, exact-discretisation transition ``f(x (..., n), dt_s) -> (..., n)``
with its analytic Jacobian ``(..., n, n)``; ``dt_s`` is a float or an array broadcasting
against ``x.shape[:-1]``. World frame: x east, y north, heading ``theta`` counter-clockwise
from +x, wrapped to ``[-pi, pi)`` on output. Turn rates and curvatures are positive to the
left (counter-clockwise).

State layouts (units):

=====  =====================================================  =======================
model  state                                                  paper 001
=====  =====================================================  =======================
CV     ``(x_m, y_m, vx_m_s, vy_m_s)``                          eq. 1-3, reordered
CTRV   ``(x_m, y_m, theta_rad, v_m_s, omega_rad_s)``           eq. 4-5
CTRA   ``(x_m, y_m, theta_rad, v_m_s, a_m_s2, omega_rad_s)``   eq. 6-9
CCA    ``(x_m, y_m, theta_rad, v_m_s, a_m_s2, c_1_m)``         eq. 10-17, re-derived
=====  =====================================================  =======================

CV keeps the position in the first two entries (the paper orders ``x, vx, y, vy``) so that
one GPS measurement function ``gps_position`` serves every model.

Paper errata handled here:

- eq. 5, second row: the last term is ``+ v/omega cos(theta)``, not ``sin(theta)``.
- eq. 11-13 take ``R = -v/omega`` and ``v(t) = v0 - a t``; we use the usual signs:
  ``omega(t) = c v(t)`` (a left turn has ``c > 0``) and ``v(t) = v0 + a t``.
- CCA, eq. 14-17: eq. 14/15 write the heading as ``theta0 + omega(t) t`` instead of the
  integral of the yaw rate; the Fresnel integrals of eq. 17 come from integrating that
  heading (its ``zeta1 = (2aT + v) sqrt(c / (2 a pi))`` completes the square of
  ``c v t + c a t^2``), while eq. 17's own heading row (in our signs
  ``theta + c v T + c a T^2 / 2``) is the correct integral. With the consistent heading
  ``theta(t) = theta0 + c s(t)``, ``s(t) = v0 t + a t^2 / 2`` (arc length), the speed factor
  ``v0 + a t = ds/dt`` is exactly the derivative of the phase over ``c``, so the position
  integral is elementary (the vehicle runs along a circle of radius ``1/c``)::

      x(T) = x0 + (sin(theta0 + c s) - sin(theta0)) / c
      y(T) = y0 - (cos(theta0 + c s) - cos(theta0)) / c,      s = v0 T + a T^2 / 2

  No Fresnel integral is needed. ``cca_transition_numerical`` integrates the continuous
  model (eq. 16 with the consistent heading) by Gauss-Legendre quadrature; the tests check
  the two against each other and show that eq. 17 is the integral of eq. 15's heading.

Small turn rates, curvatures and accelerations: all displacements are written with the
"trigonometric moments" ``M_k^c(u) = int_0^1 t^k cos(u t) dt`` and
``M_k^s(u) = int_0^1 t^k sin(u t) dt`` of the turned angle ``u``; these are evaluated by
their Taylor series for ``|u| < 0.5`` and by a stable recurrence otherwise, so the limits
``omega -> 0``, ``c -> 0`` and ``a -> 0`` need no division by zero and raise no warning.

Process noise (paper 001 section III-C-2, table I): each model has two noise variables that
drive its "constant" quantities (CV: ``vx, vy``; CTRV: ``v, omega``; CTRA: ``a, omega``;
CCA: ``a, c``). The paper gives standard deviations without a time base; we read them as
random-walk intensities (units of the quantity per square-root second), so the increment of a
quantity over a step ``dt`` has standard deviation ``sigma sqrt(dt)``, independent of the
filter rate. ``MotionModel.transition_with_noise`` applies an increment ``e`` as a linear
ramp over the step: the state is propagated with the quantity at its mid-step value
``q + e/2`` and ends at ``q + e`` (exact for CV and for the speed rows, second order
otherwise). This is the noise augmentation of the UKF (state augmented by ``e``).

Per-point kernels (numba, for the compiled UKF of :mod:`localization.compiled_ukf` and the
compiled EKF of :mod:`localization.compiled_ekf`): each transition also exists as
``*_point(x (n,), args (1,) = (dt_s,), out (n,))``, noise augmented as
``*_noisy_point(x, e (2,), args, out)``, and its Jacobian as
``*_jacobian_point(x, args, out (n, n))``, written with the same formulas in the same
order as the batched version (equal to rounding; tested). :meth:`MotionModel.process_model`,
:func:`gps_model` and :func:`pose_model` build models that carry them.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numba
import numpy as np

from localization.compiled_linalg import wrap_angle as wrap_angle_scalar
from localization.errors import EstimationError
from localization.linalg import wrap_angle
from localization.models import MeasurementModel, ProcessModel, ProcessNoise

Array = np.ndarray
"""A float array; shapes are given in the docstrings."""
Transition = Callable[..., np.ndarray]
"""A batched model function ``(x (..., n), *args) -> (..., n)`` or its Jacobian ``(..., n, n)``."""

#: Below this ``|u|`` the moments ``M_1^s`` and ``M_2^s`` use their Taylor series (their
#: closed forms cancel to ``u^2``); above it the closed forms lose at most 1e-13 relative.
_SERIES_BELOW = 0.1


def _sin_moment_series(order: int, terms: int = 5) -> tuple[float, ...]:
    """Taylor coefficients of ``M_k^s(u) / u`` in powers of ``u^2`` (truncation < 1e-18 at 0.1)."""
    return tuple(
        (-1.0) ** j / (math.factorial(2 * j + 1) * (2 * j + order + 2)) for j in range(terms)
    )


_M1S_OVER_U = _sin_moment_series(1)  # 1/3 - u^2/30 + ...
_M2S_OVER_U = _sin_moment_series(2)  # 1/4 - u^2/36 + ...


def _horner(u2: Array, coefficients: tuple[float, ...]) -> Array:
    """``sum_j coefficients[j] u2^j``, evaluated by Horner's rule."""
    acc: Array = np.asarray(coefficients[-1])
    for c in coefficients[-2::-1]:
        acc = acc * u2 + c
    return acc


def trig_moments(u: Array, max_order: int = 2) -> tuple[list[Array], list[Array]]:
    """``M_k^c(u) = int_0^1 t^k cos(u t) dt`` and ``M_k^s(u) = int_0^1 t^k sin(u t) dt``.

    Returns two lists indexed by ``k = 0..max_order`` (``max_order <= 2``), each entry shaped
    like ``u``. ``dM_k^c/du = -M_(k+1)^s`` and ``dM_k^s/du = M_(k+1)^c``. Safe at ``u = 0``
    (no division by a small number, no warning), written without cancellation where a
    half-angle form exists::

        M_0^c = sinc(u),  M_0^s = (1 - cos u)/u = sin(u/2) sinc(u/2)
        M_1^c = (sin u - M_0^s)/u = sinc(u) - sinc(u/2)^2 / 2
        M_1^s = (M_0^c - cos u)/u          (Taylor series below |u| = 0.1)
        M_2^c = (sin u - 2 M_1^s)/u = sinc(u) - 2 M_1^s/u
        M_2^s = (2 M_1^c - cos u)/u        (Taylor series below |u| = 0.1)

    with ``sinc(z) = sin(z)/z`` (integration by parts gives the recurrences).
    """
    u = np.asarray(u, dtype=float)
    # u = 0 is replaced by a tiny non-zero value: sin(z)/z is then exactly 1 and M_0^s ~ 1e-300
    u_nz = np.where(u == 0.0, 1e-300, u)
    half = 0.5 * u_nz
    sin_h = np.sin(half)
    sinc_u = np.sin(u_nz) / u_nz
    sinc_h = sin_h / half
    cos_moments = [sinc_u]
    sin_moments = [sin_h * sinc_h]
    if max_order >= 1:
        small = np.abs(u) < _SERIES_BELOW
        u2 = u * u
        u2_safe = np.where(small, 1.0, u2)
        cos_u = np.cos(u)
        m1s_over_u = np.where(small, _horner(u2, _M1S_OVER_U), (sinc_u - cos_u) / u2_safe)
        cos_moments.append(sinc_u - 0.5 * sinc_h * sinc_h)
        sin_moments.append(u * m1s_over_u)
    if max_order >= 2:
        cos_moments.append(sinc_u - 2.0 * m1s_over_u)
        m2s_over_u = np.where(
            small, _horner(u2, _M2S_OVER_U), (2.0 * cos_moments[1] - cos_u) / u2_safe
        )
        sin_moments.append(u * m2s_over_u)
    return cos_moments, sin_moments


def _check_state(x: Array, n: int, model: str) -> Array:
    x = np.asarray(x, dtype=float)
    if x.ndim == 0 or x.shape[-1] != n:
        raise EstimationError(f"{model}: the state must have shape (..., {n}), got {x.shape}")
    return x


def _rotate(theta: Array, forward: Array, left: Array) -> tuple[Array, Array]:
    """World-frame components of a vector given in the frame of heading ``theta``."""
    c, s = np.cos(theta), np.sin(theta)
    return c * forward - s * left, s * forward + c * left


def _identity(x: Array, n: int) -> Array:
    return np.broadcast_to(np.eye(n), x.shape[:-1] + (n, n)).copy()


# --------------------------------------------------------------------------------------- CV


def cv_transition(x: Array, dt_s: float | Array) -> Array:
    """CV, paper 001 eq. 3: ``x + vx dt``, ``y + vy dt``; state ``(x, y, vx, vy)``."""
    x = _check_state(x, 4, "CV")
    out = x.copy()
    out[..., 0] = x[..., 0] + x[..., 2] * dt_s
    out[..., 1] = x[..., 1] + x[..., 3] * dt_s
    return out


def cv_jacobian(x: Array, dt_s: float | Array) -> Array:
    """Jacobian ``(..., 4, 4)`` of :func:`cv_transition`."""
    x = _check_state(x, 4, "CV")
    jac = _identity(x, 4)
    jac[..., 0, 2] = dt_s
    jac[..., 1, 3] = dt_s
    return jac


# ------------------------------------------------------------------------------ CTRV / CTRA


def _ctra_parts(x: Array, dt_s: float | Array, accel: Array | None, omega: Array, jacobian: bool):
    """Shared terms of CTRV (``accel`` None) and CTRA: the local displacement and the moments.

    The displacement in the frame of the initial heading (eq. 5, 8-9 rewritten) is
    ``int_0^T (v + a t) (cos, sin)(omega t) dt = v T (M0c, M0s) + a T^2 (M1c, M1s)``;
    a Jacobian needs one order of moments more (``d/du M_k = (-M_(k+1)^s, M_(k+1)^c)``).
    """
    theta, v = x[..., 2], x[..., 3]
    dt = np.asarray(dt_s, dtype=float)
    u = omega * dt  # turned angle (rad)
    mc, ms = trig_moments(u, max_order=int(accel is not None) + int(jacobian))
    forward = v * dt * mc[0]
    left = v * dt * ms[0]
    if accel is not None:
        forward = forward + accel * dt**2 * mc[1]
        left = left + accel * dt**2 * ms[1]
    return theta, v, dt, u, mc, ms, forward, left


def _ctra_like_transition(x: Array, dt_s, accel: Array | None, omega: Array) -> Array:
    theta, v, dt, u, _, _, forward, left = _ctra_parts(x, dt_s, accel, omega, jacobian=False)
    dx, dy = _rotate(theta, forward, left)
    out = x.copy()
    out[..., 0] = x[..., 0] + dx
    out[..., 1] = x[..., 1] + dy
    out[..., 2] = wrap_angle(theta + u)
    if accel is not None:
        out[..., 3] = v + accel * dt
    return out


def _ctra_like_jacobian(x: Array, dt_s, accel: Array | None, omega: Array, i_omega: int) -> Array:
    """Jacobian of CTRV/CTRA; the acceleration (CTRA) sits at index 4."""
    theta, v, dt, _, mc, ms, forward, left = _ctra_parts(x, dt_s, accel, omega, jacobian=True)
    jac = _identity(x, x.shape[-1])
    dx, dy = _rotate(theta, forward, left)
    jac[..., 0, 2], jac[..., 1, 2] = -dy, dx
    jac[..., 0, 3], jac[..., 1, 3] = _rotate(theta, dt * mc[0], dt * ms[0])
    # d/domega of (M_k^c, M_k^s)(omega T) = T (-M_(k+1)^s, M_(k+1)^c)
    d_forward = -dt * dt * v * ms[1]
    d_left = dt * dt * v * mc[1]
    if accel is not None:
        d_forward = d_forward - dt**3 * accel * ms[2]
        d_left = d_left + dt**3 * accel * mc[2]
        jac[..., 0, 4], jac[..., 1, 4] = _rotate(theta, dt**2 * mc[1], dt**2 * ms[1])
        jac[..., 3, 4] = dt
    jac[..., 0, i_omega], jac[..., 1, i_omega] = _rotate(theta, d_forward, d_left)
    jac[..., 2, i_omega] = dt
    return jac


def _along_arc(x: Array, theta: Array, length: Array, turn: Array) -> Array:
    """``x`` with its position moved along a circular arc and its heading turned (wrapped).

    The arc starts at heading ``theta``, has the signed ``length`` (m) and turns by ``turn``
    (rad). Its displacement ``length (M_0^c, M_0^s)(turn)`` in the frame of ``theta`` is the
    chord, ``(M_0^c, M_0^s)(u) = sinc(u/2) (cos, sin)(u/2)``, so in the world frame it is
    ``length sinc(turn/2) (cos, sin)(theta + turn/2)``: half the numpy calls of the moment
    form (which the Jacobians keep), equal to it to rounding (1 ulp of the position).
    ``sinc(h) = sin(a)/a`` with ``a = hypot(h, 1e-300)``, which is ``|h|`` unless ``|h|`` is
    below about 1e-290, where the ratio is exactly 1 anyway (``sinc`` is even): no turn
    needs no branch and gives the straight line bit for bit.
    """
    half = 0.5 * turn
    a = np.hypot(half, 1e-300)
    chord = np.sin(a)
    chord /= a
    chord *= length  # the chord length (m)
    direction = theta + half
    out = x.copy()
    np.add(x[..., 0], chord * np.cos(direction), out=out[..., 0])
    np.add(x[..., 1], chord * np.sin(direction), out=out[..., 1])
    out[..., 2] = wrap_angle(theta + turn)
    return out


def ctrv_transition(x: Array, dt_s: float | Array) -> Array:
    """CTRV, paper 001 eq. 5 (corrected); state ``(x, y, theta, v, omega)``.

    An arc of length ``v T`` turning by ``omega T`` (:func:`_along_arc`).
    """
    x = _check_state(x, 5, "CTRV")
    dt = dt_s if isinstance(dt_s, float) else np.asarray(dt_s, dtype=float)
    return _along_arc(x, x[..., 2], x[..., 3] * dt, x[..., 4] * dt)


def ctrv_jacobian(x: Array, dt_s: float | Array) -> Array:
    """Jacobian ``(..., 5, 5)`` of :func:`ctrv_transition`."""
    x = _check_state(x, 5, "CTRV")
    return _ctra_like_jacobian(x, dt_s, None, x[..., 4], 4)


def ctra_transition(x: Array, dt_s: float | Array) -> Array:
    """CTRA, paper 001 eq. 7-9; state ``(x, y, theta, v, a, omega)``."""
    x = _check_state(x, 6, "CTRA")
    return _ctra_like_transition(x, dt_s, x[..., 4], x[..., 5])


def ctra_jacobian(x: Array, dt_s: float | Array) -> Array:
    """Jacobian ``(..., 6, 6)`` of :func:`ctra_transition`."""
    x = _check_state(x, 6, "CTRA")
    return _ctra_like_jacobian(x, dt_s, x[..., 4], x[..., 5], 5)


# -------------------------------------------------------------------------------------- CCA


def _cca_parts(x: Array, dt_s: float | Array, jacobian: bool):
    theta, v, a, c = x[..., 2], x[..., 3], x[..., 4], x[..., 5]
    dt = np.asarray(dt_s, dtype=float)
    s = v * dt + 0.5 * a * dt**2  # arc length (m), signed
    u = c * s  # turned angle (rad)
    mc, ms = trig_moments(u, max_order=int(jacobian))
    return theta, v, a, c, dt, s, u, mc, ms


def cca_transition(x: Array, dt_s: float | Array) -> Array:
    """CCA (constant curvature and acceleration), re-derived closed form of paper 001 eq. 17.

    State ``(x, y, theta, v, a, c)``. With ``s = v T + a T^2 / 2``:
    ``(x, y) += R(theta) s (M_0^c(c s), M_0^s(c s))`` (a circular arc of length ``s``,
    evaluated as its chord by :func:`_along_arc`), ``theta += c s``, ``v += a T``; ``a`` and
    ``c`` are constant.
    """
    x = _check_state(x, 6, "CCA")
    theta, v, a, c = x[..., 2], x[..., 3], x[..., 4], x[..., 5]
    dt = np.asarray(dt_s, dtype=float)
    s = v * dt + 0.5 * a * dt**2  # arc length (m), signed, as in _cca_parts
    out = _along_arc(x, theta, s, c * s)
    out[..., 3] = v + a * dt
    return out


def cca_jacobian(x: Array, dt_s: float | Array) -> Array:
    """Jacobian ``(..., 6, 6)`` of :func:`cca_transition`."""
    x = _check_state(x, 6, "CCA")
    theta, _, _, c, dt, s, u, mc, ms = _cca_parts(x, dt_s, jacobian=True)
    jac = _identity(x, 6)
    dx, dy = _rotate(theta, s * mc[0], s * ms[0])
    jac[..., 0, 2], jac[..., 1, 2] = -dy, dx
    # d(local)/ds = (cos u, sin u): the tangent at the end of the arc
    tx, ty = _rotate(theta, np.cos(u), np.sin(u))
    jac[..., 0, 3], jac[..., 1, 3] = tx * dt, ty * dt
    jac[..., 0, 4], jac[..., 1, 4] = tx * 0.5 * dt**2, ty * 0.5 * dt**2
    jac[..., 0, 5], jac[..., 1, 5] = _rotate(theta, -s * s * ms[1], s * s * mc[1])
    jac[..., 2, 3] = c * dt
    jac[..., 2, 4] = 0.5 * c * dt**2
    jac[..., 2, 5] = s
    jac[..., 3, 4] = dt
    return jac


def cca_transition_numerical(x: Array, dt_s: float | Array, nodes: int = 24) -> Array:
    """CCA by Gauss-Legendre quadrature of the continuous model (paper 001 eq. 16).

    ``x(T) = x0 + int_0^T v(t) cos(theta(t)) dt`` (same for ``y`` with ``sin``), with
    ``v(t) = v0 + a t`` and the consistent heading ``theta(t) = theta0 + c (v0 t + a t^2/2)``.
    The reference against which :func:`cca_transition` is tested; ``nodes`` quadrature nodes.
    """
    x = _check_state(x, 6, "CCA")
    theta, v, a, c = (x[..., i, None] for i in range(2, 6))
    dt = np.asarray(dt_s, dtype=float)[..., None]
    nodes_unit, weights_unit = np.polynomial.legendre.leggauss(nodes)
    t = 0.5 * (nodes_unit + 1.0) * dt  # (..., nodes) on [0, T]
    speed = v + a * t
    heading = theta + c * (v * t + 0.5 * a * t * t)
    w = 0.5 * weights_unit * dt
    out = cca_transition(x, dt_s)  # heading, speed rows are exact polynomials
    out[..., 0] = x[..., 0] + np.sum(w * speed * np.cos(heading), axis=-1)
    out[..., 1] = x[..., 1] + np.sum(w * speed * np.sin(heading), axis=-1)
    return out


# ---------------------------------------------------------------------- measurement models


def gps_position(x: Array) -> Array:
    """GPS position measurement ``(..., 2) = (x_m, y_m)``: the first two entries of every layout."""
    return np.asarray(x, dtype=float)[..., :2]


def _leading_jacobian(x: Array, m: int) -> Array:
    """Jacobian ``(..., m, n)`` of ``x[..., :m]``."""
    x = np.asarray(x, dtype=float)
    jac = np.zeros(x.shape[:-1] + (m, x.shape[-1]))
    for j in range(m):
        jac[..., j, j] = 1.0
    return jac


def gps_jacobian(x: Array) -> Array:
    """Jacobian ``(..., 2, n)`` of :func:`gps_position`."""
    return _leading_jacobian(x, 2)


def pose_measurement(x: Array) -> Array:
    """Pose measurement ``(..., 3) = (x_m, y_m, theta_rad)`` of the CTRV, CTRA and CCA layouts."""
    return np.asarray(x, dtype=float)[..., :3]


def pose_jacobian(x: Array) -> Array:
    """Jacobian ``(..., 3, n)`` of :func:`pose_measurement`."""
    return _leading_jacobian(x, 3)


def cv_odometry(x: Array) -> Array:
    """CV odometry: the speed ``(..., 1) = (hypot(vx, vy),)`` m/s (CV has no yaw rate)."""
    x = _check_state(x, 4, "CV")
    return np.hypot(x[..., 2], x[..., 3])[..., None]


def cv_odometry_jacobian(x: Array) -> Array:
    """Jacobian ``(..., 1, 4)`` of :func:`cv_odometry`; zero at standstill (no division by 0)."""
    x = _check_state(x, 4, "CV")
    speed = np.hypot(x[..., 2], x[..., 3])
    safe = np.where(speed > 0.0, speed, 1.0)
    jac = np.zeros(x.shape[:-1] + (1, 4))
    jac[..., 0, 2] = np.where(speed > 0.0, x[..., 2] / safe, 0.0)
    jac[..., 0, 3] = np.where(speed > 0.0, x[..., 3] / safe, 0.0)
    return jac


def _speed_and_yaw_rate_entries(model: str, n: int, i_speed: int, i_yaw_rate: int):
    """Odometry ``(v, omega)`` read directly from two state entries, and its Jacobian."""

    def odometry(x: Array) -> Array:
        return _check_state(x, n, model)[..., [i_speed, i_yaw_rate]]

    def jacobian(x: Array) -> Array:
        x = _check_state(x, n, model)
        jac = np.zeros(x.shape[:-1] + (2, n))
        jac[..., 0, i_speed] = jac[..., 1, i_yaw_rate] = 1.0
        return jac

    odometry.__doc__ = f"{model} odometry ``(..., 2) = (v_m_s, omega_rad_s)``."
    jacobian.__doc__ = f"Jacobian ``(..., 2, {n})`` of the {model} odometry."
    return odometry, jacobian


ctrv_odometry, ctrv_odometry_jacobian = _speed_and_yaw_rate_entries("CTRV", 5, 3, 4)
ctra_odometry, ctra_odometry_jacobian = _speed_and_yaw_rate_entries("CTRA", 6, 3, 5)


def cca_odometry(x: Array) -> Array:
    """CCA odometry ``(..., 2) = (v_m_s, omega_rad_s = c v)``."""
    x = _check_state(x, 6, "CCA")
    return np.stack([x[..., 3], x[..., 5] * x[..., 3]], axis=-1)


def cca_odometry_jacobian(x: Array) -> Array:
    """Jacobian ``(..., 2, 6)`` of :func:`cca_odometry`."""
    x = _check_state(x, 6, "CCA")
    jac = np.zeros(x.shape[:-1] + (2, 6))
    jac[..., 0, 3] = 1.0
    jac[..., 1, 3] = x[..., 5]
    jac[..., 1, 5] = x[..., 3]
    return jac


# ------------------------------------------------------------------ per-point kernels (numba)
# One sigma point per call, for localization.compiled_ukf: the formulas of the batched
# functions above, in the same order of operations.


@numba.njit(cache=True)
def _along_arc_point(x, theta, length, turn, out) -> None:
    """:func:`_along_arc` for one state ``x (n,)`` into ``out (n,)``."""
    out[:] = x
    half = 0.5 * turn
    a = math.hypot(half, 1e-300)
    chord = math.sin(a) / a * length
    direction = theta + half
    out[0] = x[0] + chord * math.cos(direction)
    out[1] = x[1] + chord * math.sin(direction)
    out[2] = wrap_angle_scalar(theta + turn)


@numba.njit(cache=True)
def cv_point(x, args, out) -> None:
    """:func:`cv_transition` of one state ``x (4,)``, ``args = (dt_s,)``, into ``out (4,)``."""
    dt = args[0]
    out[:] = x
    out[0] = x[0] + x[2] * dt
    out[1] = x[1] + x[3] * dt


@numba.njit(cache=True)
def ctrv_point(x, args, out) -> None:
    """:func:`ctrv_transition` of one state ``x (5,)``, ``args = (dt_s,)``, into ``out (5,)``."""
    dt = args[0]
    _along_arc_point(x, x[2], x[3] * dt, x[4] * dt, out)


@numba.njit(cache=True)
def ctra_point(x, args, out) -> None:
    """:func:`ctra_transition` of one state ``x (6,)``, ``args = (dt_s,)``, into ``out (6,)``
    (the moments of :func:`trig_moments` for one turned angle ``u``)."""
    dt = args[0]
    theta, v, accel, omega = x[2], x[3], x[4], x[5]
    u = omega * dt
    mc0, mc1, _, ms0, ms1, _ = _trig_moments_point(u)
    forward = v * dt * mc0 + accel * (dt * dt) * mc1
    left = v * dt * ms0 + accel * (dt * dt) * ms1
    c, s = math.cos(theta), math.sin(theta)
    out[:] = x
    out[0] = x[0] + (c * forward - s * left)
    out[1] = x[1] + (s * forward + c * left)
    out[2] = wrap_angle_scalar(theta + u)
    out[3] = v + accel * dt


@numba.njit(cache=True)
def cca_point(x, args, out) -> None:
    """:func:`cca_transition` of one state ``x (6,)``, ``args = (dt_s,)``, into ``out (6,)``."""
    dt = args[0]
    v, a, c = x[3], x[4], x[5]
    s = v * dt + 0.5 * a * (dt * dt)
    _along_arc_point(x, x[2], s, c * s, out)
    out[3] = v + a * dt


@numba.njit(cache=True)
def _half_increment(values, noise, first) -> None:
    """``values[first + j] += noise[j] / 2``: half of the ramp of
    :meth:`MotionModel.transition_with_noise` (applied to the state before the transition, at
    mid-step, and to its image after it)."""
    for j in range(noise.shape[0]):
        values[first + j] += 0.5 * noise[j]


@numba.njit(cache=True)
def cv_noisy_point(x, noise, args, out) -> None:
    """CV with the increments ``noise (2,)`` of ``(vx, vy)`` (augmented noise); ``x`` overwritten."""
    _half_increment(x, noise, 2)
    cv_point(x, args, out)
    _half_increment(out, noise, 2)


@numba.njit(cache=True)
def ctrv_noisy_point(x, noise, args, out) -> None:
    """CTRV with the increments ``noise (2,)`` of ``(v, omega)`` (augmented noise); ``x`` overwritten."""
    _half_increment(x, noise, 3)
    ctrv_point(x, args, out)
    _half_increment(out, noise, 3)


@numba.njit(cache=True)
def ctra_noisy_point(x, noise, args, out) -> None:
    """CTRA with the increments ``noise (2,)`` of ``(a, omega)`` (augmented noise); ``x`` overwritten."""
    _half_increment(x, noise, 4)
    ctra_point(x, args, out)
    _half_increment(out, noise, 4)


@numba.njit(cache=True)
def cca_noisy_point(x, noise, args, out) -> None:
    """CCA with the increments ``noise (2,)`` of ``(a, c)`` (augmented noise); ``x`` overwritten."""
    _half_increment(x, noise, 4)
    cca_point(x, args, out)
    _half_increment(out, noise, 4)


@numba.njit(cache=True)
def leading_entries_point(x, args, out) -> None:
    """``out (m,) = x[:m]``: :func:`gps_position` (``m = 2``) or :func:`pose_measurement` (``m = 3``)."""
    for j in range(out.shape[0]):
        out[j] = x[j]


@numba.njit(cache=True)
def leading_entries_jacobian_point(x, args, out) -> None:
    """``out (m, n) = [I 0]``: the Jacobian of :func:`leading_entries_point` (:func:`gps_jacobian`,
    :func:`pose_jacobian`)."""
    _identity_point(out)


# Per-point Jacobian kernels (for localization.compiled_ekf): the batched Jacobians above for
# one state, ``F(x (n,), args = (dt_s,), out (n, n))``, same formulas in the same order.


@numba.njit(cache=True)
def _trig_moments_point(u):
    """:func:`trig_moments` to order 2 of one angle ``u``: ``(M0c, M1c, M2c, M0s, M1s, M2s)``."""
    u_nz = 1e-300 if u == 0.0 else u
    half = 0.5 * u_nz
    sin_h = math.sin(half)
    sinc_u = math.sin(u_nz) / u_nz
    sinc_h = sin_h / half
    u2 = u * u
    cos_u = math.cos(u)
    small = abs(u) < _SERIES_BELOW
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


@numba.njit(cache=True)
def cv_jacobian_point(x, args, out) -> None:
    """:func:`cv_jacobian` of one state ``x (4,)``, ``args = (dt_s,)``, into ``out (4, 4)``."""
    dt = args[0]
    _identity_point(out)
    out[0, 2] = dt
    out[1, 3] = dt


@numba.njit(cache=True)
def _ctra_like_jacobian_point(x, dt, accel, omega, i_omega, out) -> None:
    """:func:`_ctra_like_jacobian` of one state (CTRV: ``accel`` is NaN and unused, no index 4 row)."""
    theta, v = x[2], x[3]
    has_accel = i_omega == 5
    mc0, mc1, mc2, ms0, ms1, ms2 = _trig_moments_point(omega * dt)
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
    """:func:`ctrv_jacobian` of one state ``x (5,)``, ``args = (dt_s,)``, into ``out (5, 5)``."""
    _ctra_like_jacobian_point(x, args[0], math.nan, x[4], 4, out)


@numba.njit(cache=True)
def ctra_jacobian_point(x, args, out) -> None:
    """:func:`ctra_jacobian` of one state ``x (6,)``, ``args = (dt_s,)``, into ``out (6, 6)``."""
    _ctra_like_jacobian_point(x, args[0], x[4], x[5], 5, out)


@numba.njit(cache=True)
def cca_jacobian_point(x, args, out) -> None:
    """:func:`cca_jacobian` of one state ``x (6,)``, ``args = (dt_s,)``, into ``out (6, 6)``."""
    dt = args[0]
    theta, v, a, c = x[2], x[3], x[4], x[5]
    s = v * dt + 0.5 * a * (dt * dt)
    u = c * s
    mc0, mc1, _, ms0, ms1, _ = _trig_moments_point(u)
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


def gps_model(R: Array) -> MeasurementModel:
    """The GPS position model ``(x_m, y_m)`` with noise ``R (2, 2)`` (m^2), with its kernels."""
    return MeasurementModel(
        gps_position,
        R,
        jacobian=gps_jacobian,
        point=leading_entries_point,
        jacobian_point=leading_entries_jacobian_point,
    )


def pose_model(R: Array) -> MeasurementModel:
    """The pose model ``(x_m, y_m, theta_rad)`` (CTRV, CTRA, CCA; heading an angle) with noise
    ``R (3, 3)`` (m^2, m^2, rad^2), with its kernels."""
    return MeasurementModel(
        pose_measurement,
        R,
        jacobian=pose_jacobian,
        angle_indices=(2,),
        point=leading_entries_point,
        jacobian_point=leading_entries_jacobian_point,
    )


# ----------------------------------------------------------------------------- the records


@dataclass(frozen=True)
class MotionModel:
    """One motion model with its measurement functions and process noise (paper 001).

    Attributes:
        name: ``"CV"``, ``"CTRV"``, ``"CTRA"`` or ``"CCA"``.
        state_names: names (with units) of the ``n`` state entries.
        angle_indices: state entries that are angles (wrapped to ``[-pi, pi)``).
        transition: ``f(x (..., n), dt_s) -> (..., n)``.
        jacobian: ``F(x (..., n), dt_s) -> (..., n, n)``.
        odometry: ``h(x (..., n)) -> (..., m)``: the odometry quantities the model explains.
        odometry_jacobian: ``H(x (..., n)) -> (..., m, n)``.
        odometry_names: what ``odometry`` returns (``"speed"``, ``"yaw_rate"``).
        noise_names: the process-noise variables of paper 001 table I.
        noise_indices: the state entries each noise variable drives (consecutive, increasing).
        noise_intensity: table I standard deviations, read as intensities per sqrt(second).
        point: the per-point kernel of ``transition`` (compiled UKF, additive noise).
        noisy_point: the per-point kernel of ``transition_with_noise`` (augmented noise).
        jacobian_point: the per-point kernel of ``jacobian`` (compiled EKF).
    """

    name: str
    state_names: tuple[str, ...]
    angle_indices: tuple[int, ...]
    transition: Transition
    jacobian: Transition
    odometry: Callable[[Array], Array]
    odometry_jacobian: Callable[[Array], Array]
    odometry_names: tuple[str, ...]
    noise_names: tuple[str, ...]
    noise_indices: tuple[int, ...]
    noise_intensity: tuple[float, ...]
    point: Callable[..., None]
    noisy_point: Callable[..., None]
    jacobian_point: Callable[..., None]

    def __post_init__(self) -> None:
        q = len(self.noise_names)
        first = self.noise_indices[0] if self.noise_indices else -1
        if (
            q == 0
            or len(self.noise_intensity) != q
            or self.noise_indices != tuple(range(first, first + q))
        ):
            raise EstimationError(
                f"{self.name}: noise_indices {self.noise_indices} must be {q} consecutive entries, "
                f"one per noise variable, with one intensity each"
            )

    @property
    def n(self) -> int:
        """State dimension."""
        return len(self.state_names)

    def process_noise_std(self, dt_s: float) -> Array:
        """Standard deviations ``(q,)`` of the per-step increments: ``intensity * sqrt(dt)``."""
        if not (math.isfinite(dt_s) and dt_s > 0.0):
            raise EstimationError(f"{self.name}: dt_s must be finite and > 0, got {dt_s!r}")
        return np.asarray(self.noise_intensity) * math.sqrt(dt_s)

    def transition_with_noise(self, x: Array, noise: Array, dt_s: float | Array) -> Array:
        """Noise-augmented transition ``f(x (..., n), e (..., q), dt) -> (..., n)``.

        The driven quantities ramp linearly by ``e`` over the step: the state is propagated
        with them at ``q + e/2`` and they end at ``q + e`` (module docstring).
        """
        driven = slice(self.noise_indices[0], self.noise_indices[-1] + 1)  # contiguous entries
        half = 0.5 * np.asarray(noise, dtype=float)
        x_mid = np.array(x, dtype=float, copy=True)
        x_mid[..., driven] += half
        out = self.transition(x_mid, dt_s)
        out[..., driven] += half
        return out

    def process_model(self, Q: Array, noise: ProcessNoise = ProcessNoise.ADDITIVE) -> ProcessModel:
        """This model as a :class:`~localization.models.ProcessModel` with its kernel.

        ``noise="additive"``: ``f = transition`` with ``Q (n, n)`` and the Jacobian;
        ``noise="augmented"``: ``f = transition_with_noise`` with ``Q (2, 2)`` the covariance of
        the increments (e.g. ``np.diag(self.process_noise_std(dt_s) ** 2)``). Either way the
        UKF takes its compiled path (the step's argument is ``dt_s``); additive, the EKF too.
        """
        if noise == ProcessNoise.AUGMENTED:
            return ProcessModel(
                self.transition_with_noise, Q, noise=ProcessNoise.AUGMENTED, point=self.noisy_point
            )
        return ProcessModel(
            self.transition,
            Q,
            jacobian=self.jacobian,
            noise=noise,
            point=self.point,
            jacobian_point=self.jacobian_point,
        )


CV = MotionModel(
    name="CV",
    state_names=("x_m", "y_m", "vx_m_s", "vy_m_s"),
    angle_indices=(),
    transition=cv_transition,
    jacobian=cv_jacobian,
    odometry=cv_odometry,
    odometry_jacobian=cv_odometry_jacobian,
    odometry_names=("speed",),
    noise_names=("e_vx", "e_vy"),
    noise_indices=(2, 3),
    point=cv_point,
    noisy_point=cv_noisy_point,
    jacobian_point=cv_jacobian_point,
    noise_intensity=(0.5, 0.5),
)
CTRV = MotionModel(
    name="CTRV",
    state_names=("x_m", "y_m", "theta_rad", "v_m_s", "omega_rad_s"),
    angle_indices=(2,),
    transition=ctrv_transition,
    jacobian=ctrv_jacobian,
    odometry=ctrv_odometry,
    odometry_jacobian=ctrv_odometry_jacobian,
    odometry_names=("speed", "yaw_rate"),
    noise_names=("e_v", "e_omega"),
    noise_indices=(3, 4),
    point=ctrv_point,
    noisy_point=ctrv_noisy_point,
    jacobian_point=ctrv_jacobian_point,
    noise_intensity=(0.5, 0.25),
)
CTRA = MotionModel(
    name="CTRA",
    state_names=("x_m", "y_m", "theta_rad", "v_m_s", "a_m_s2", "omega_rad_s"),
    angle_indices=(2,),
    transition=ctra_transition,
    jacobian=ctra_jacobian,
    odometry=ctra_odometry,
    odometry_jacobian=ctra_odometry_jacobian,
    odometry_names=("speed", "yaw_rate"),
    noise_names=("e_a", "e_omega"),
    noise_indices=(4, 5),
    point=ctra_point,
    noisy_point=ctra_noisy_point,
    jacobian_point=ctra_jacobian_point,
    noise_intensity=(0.5, 0.25),
)
CCA = MotionModel(
    name="CCA",
    state_names=("x_m", "y_m", "theta_rad", "v_m_s", "a_m_s2", "c_1_m"),
    angle_indices=(2,),
    transition=cca_transition,
    jacobian=cca_jacobian,
    odometry=cca_odometry,
    odometry_jacobian=cca_odometry_jacobian,
    odometry_names=("speed", "yaw_rate"),
    noise_names=("e_a", "e_c"),
    noise_indices=(4, 5),
    point=cca_point,
    noisy_point=cca_noisy_point,
    jacobian_point=cca_jacobian_point,
    noise_intensity=(0.5, 0.25),
)

#: The four models of paper 001, by name.
MODELS: dict[str, MotionModel] = {m.name: m for m in (CV, CTRV, CTRA, CCA)}
