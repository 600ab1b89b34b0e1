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

One source per formula. Each transition, its noise-augmented form and its Jacobian are
written once, as a per-point numba kernel in :mod:`localization.compiled.motion`
(``*_point(x (n,), args (1,) = (dt_s,), out (n,))``, ``*_noisy_point(x, e (2,), args, out)``,
``*_jacobian_point(x, args, out (n, n))``); the batched functions here run those kernels over
the rows of a batch, so a batched result is its states' per-point results bit for bit, and the
compiled UKF and EKF inline the same kernels. :meth:`MotionModel.process_model`,
:func:`gps_model` and :func:`pose_model` build models that carry them. The independent checks
of the formulas (finite differences, quadrature, closed-form limits) are the tests.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from localization.compiled import motion as kernels
from localization.errors import EstimationError
from localization.models import MeasurementModel, ProcessModel, ProcessNoise

Array = np.ndarray
"""A float array; shapes are given in the docstrings."""
Transition = Callable[..., np.ndarray]
"""A batched model function ``(x (..., n), *args) -> (..., n)`` or its Jacobian ``(..., n, n)``."""


def _check_state(x: Array, n: int, model: str) -> Array:
    x = np.asarray(x, dtype=float)
    if x.ndim == 0 or x.shape[-1] != n:
        raise EstimationError(f"{model}: the state must have shape (..., {n}), got {x.shape}")
    return x


def _as_rows(values: Array, shape: tuple[int, ...], width: int) -> Array:
    """``values`` broadcast to ``shape + (width,)`` as a fresh C-contiguous float array ``(N, width)``."""
    return np.array(np.broadcast_to(values, shape + (width,)), dtype=np.float64, order="C").reshape(
        -1, width
    )


def _rows(x: Array, n: int, model: str, dt_s: float | Array, noise: Array | None = None):
    """``(batch shape, x rows (N, n), dt rows (N,), noise rows (N, 2) or None)``: ``x (..., n)``,
    ``dt_s`` and the noise increments ``(..., 2)`` broadcast against each other's batch axes."""
    x = _check_state(x, n, model)
    dt = np.asarray(dt_s, dtype=float)
    batches = [x.shape[:-1], dt.shape]
    if noise is not None:
        noise = np.asarray(noise, dtype=float)
        batches.append(noise.shape[:-1])
    shape = np.broadcast_shapes(*batches)
    noise_rows = None if noise is None else _as_rows(noise, shape, noise.shape[-1])
    return shape, _as_rows(x, shape, n), _as_rows(dt[..., None], shape, 1)[:, 0], noise_rows


def _batched(name: str, n: int) -> tuple[Transition, Transition]:
    """The batched transition and Jacobian of the built-in model ``name`` with ``n`` states:
    the kernels of :mod:`localization.compiled.motion` run over the rows of the batch."""
    number = kernels.MODEL_NUMBERS[name]

    def transition(x: Array, dt_s: float | Array) -> Array:
        shape, rows, dts, _ = _rows(x, n, name, dt_s)
        out = np.empty_like(rows)
        kernels.transition_rows(number, rows, dts, out)
        return out.reshape(shape + (n,))

    def jacobian(x: Array, dt_s: float | Array) -> Array:
        shape, rows, dts, _ = _rows(x, n, name, dt_s)
        out = np.empty((rows.shape[0], n, n))
        kernels.jacobian_rows(number, rows, dts, out)
        return out.reshape(shape + (n, n))

    return transition, jacobian


def trig_moments(u: Array, max_order: int = 2) -> tuple[list[Array], list[Array]]:
    """``M_k^c(u) = int_0^1 t^k cos(u t) dt`` and ``M_k^s(u) = int_0^1 t^k sin(u t) dt``.

    Returns two lists indexed by ``k = 0..max_order`` (``max_order <= 2``), each entry shaped
    like ``u``; the formulas are those of :func:`localization.compiled.motion.trig_moments_point`
    (run over the entries of ``u``).
    """
    u = np.asarray(u, dtype=float)
    flat = np.array(u, dtype=np.float64, order="C").reshape(-1)
    out = np.empty((flat.shape[0], 6))
    kernels.trig_moment_rows(flat, out)
    moments = [out[:, k].reshape(u.shape) for k in range(6)]
    return moments[: max_order + 1], moments[3 : 4 + max_order]


cv_transition, cv_jacobian = _batched("CV", 4)
cv_transition.__doc__ = """CV, paper 001 eq. 3: ``x (..., 4) = (x, y, vx, vy)`` over ``dt_s`` -> ``(..., 4)``
(:func:`localization.compiled.motion.cv_point` per state)."""
cv_jacobian.__doc__ = """Jacobian ``(..., 4, 4)`` of :func:`cv_transition`."""
ctrv_transition, ctrv_jacobian = _batched("CTRV", 5)
ctrv_transition.__doc__ = """CTRV, paper 001 eq. 5 (corrected): ``x (..., 5) = (x, y, theta, v, omega)``
over ``dt_s`` -> ``(..., 5)`` (:func:`localization.compiled.motion.ctrv_point` per state)."""
ctrv_jacobian.__doc__ = """Jacobian ``(..., 5, 5)`` of :func:`ctrv_transition`."""
ctra_transition, ctra_jacobian = _batched("CTRA", 6)
ctra_transition.__doc__ = """CTRA, paper 001 eq. 7-9: ``x (..., 6) = (x, y, theta, v, a, omega)`` over
``dt_s`` -> ``(..., 6)`` (:func:`localization.compiled.motion.ctra_point` per state)."""
ctra_jacobian.__doc__ = """Jacobian ``(..., 6, 6)`` of :func:`ctra_transition`."""
cca_transition, cca_jacobian = _batched("CCA", 6)
cca_transition.__doc__ = """CCA, the re-derived closed form of paper 001 eq. 17: ``x (..., 6) = (x, y,
theta, v, a, c)`` over ``dt_s`` -> ``(..., 6)`` (:func:`localization.compiled.motion.cca_point`
per state)."""
cca_jacobian.__doc__ = """Jacobian ``(..., 6, 6)`` of :func:`cca_transition`."""


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


def gps_model(R: Array) -> MeasurementModel:
    """The GPS position model ``(x_m, y_m)`` with noise ``R (2, 2)`` (m^2), with its kernels."""
    return MeasurementModel(
        gps_position,
        R,
        jacobian=gps_jacobian,
        point=kernels.leading_entries_point,
        jacobian_point=kernels.leading_entries_jacobian_point,
    )


def pose_model(R: Array) -> MeasurementModel:
    """The pose model ``(x_m, y_m, theta_rad)`` (CTRV, CTRA, CCA; heading an angle) with noise
    ``R (3, 3)`` (m^2, m^2, rad^2), with its kernels."""
    return MeasurementModel(
        pose_measurement,
        R,
        jacobian=pose_jacobian,
        angle_indices=(2,),
        point=kernels.leading_entries_point,
        jacobian_point=kernels.leading_entries_jacobian_point,
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
        with them at ``q + e/2`` and they end at ``q + e`` (module docstring; the kernel
        ``noisy_point`` per state).
        """
        shape, rows, dts, noise_rows = _rows(x, self.n, self.name, dt_s, noise)
        out = np.empty_like(rows)
        kernels.noisy_transition_rows(kernels.MODEL_NUMBERS[self.name], rows, noise_rows, dts, out)
        return out.reshape(shape + (self.n,))

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
    point=kernels.cv_point,
    noisy_point=kernels.cv_noisy_point,
    jacobian_point=kernels.cv_jacobian_point,
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
    point=kernels.ctrv_point,
    noisy_point=kernels.ctrv_noisy_point,
    jacobian_point=kernels.ctrv_jacobian_point,
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
    point=kernels.ctra_point,
    noisy_point=kernels.ctra_noisy_point,
    jacobian_point=kernels.ctra_jacobian_point,
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
    point=kernels.cca_point,
    noisy_point=kernels.cca_noisy_point,
    jacobian_point=kernels.cca_jacobian_point,
    noise_intensity=(0.5, 0.25),
)

#: The four models of paper 001, by name.
MODELS: dict[str, MotionModel] = {m.name: m for m in (CV, CTRV, CTRA, CCA)}
