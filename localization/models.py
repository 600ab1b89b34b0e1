"""Process and measurement models as the filters consume them (frozen, validated once).

Model functions are written for a leading batch axis, so that one call evaluates all
sigma points of all runs:

- ``f(x (..., n), *args) -> (..., n)`` (additive noise), or
  ``f(x (..., n), w (..., q), *args) -> (..., n)`` (augmented noise, paper 001);
- ``F(x (..., n), *args) -> (..., n, n)``: the Jacobian ``df/dx`` (EKF, IEKF, MEKF);
- ``h(x (..., n), *args) -> (..., m)`` and ``H(x (..., n), *args) -> (..., m, n)``.

``*args`` are the step's extra inputs (control ``u``, ``dt_s``, the time index...), passed
through unchanged by the EKF family. The unscented filters evaluate the models on sigma
points ``(B, 2n + 1, n)``: an array argument whose leading axes equal the belief's batch
shape ``(B,)`` is per-run and gets a sigma axis after them (``(B,)`` -> ``(B, 1)``,
``(B, k)`` -> ``(B, 1, k)``); floats and other arrays pass unchanged (they are shared).

A model may also carry a per-point kernel (``point=``): the same function for ONE sigma point,
compiled with ``numba.njit``, which lets the UKF take its compiled path
(:mod:`localization.compiled.ukf`, about 30 times faster for one filter):

- ``f(x (n,), args (k,), out (n,))`` (additive) or ``f(x (n,), w (q,), args (k,), out (n,))``
  (augmented), ``h(x (n,), args (k,), out (m,))``: the result is written into ``out``;
  ``args`` are the step's arguments packed as floats, each flattened, in order (per-run
  arrays give their run's entries); ``x`` and ``w`` are scratch copies the kernel may overwrite.

With a per-point Jacobian kernel as well (``jacobian_point=``, used together with ``point`` and
``jacobian``; additive noise), the EKF takes its compiled path (:mod:`localization.compiled.ekf`):

- ``F(x (n,), args (k,), out (n, n))``, ``H(x (n,), args (k,), out (m, n))``: every entry of
  ``out`` written.

The kernels must compute the batched functions to rounding: the numpy path (the reference, and
the fallback whenever a compiled step cannot run or fails) uses the batched ones.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from enum import StrEnum

import numba
import numpy as np

from localization.errors import EstimationError
from localization.linalg import symmetrise, wrap_columns


def _check_kernel(owner: str, point, name: str = "point") -> None:
    """Refuse a kernel ``name`` that is not a numba-compiled function (or ``None``)."""
    if point is not None and not isinstance(point, numba.core.registry.CPUDispatcher):
        raise EstimationError(
            f"{owner}: {name} must be a numba.njit-compiled function or None, got {point!r}"
        )


def _noise_covariance(matrix: np.ndarray, owner: str, name: str) -> np.ndarray:
    """``matrix (..., k, k)`` as a read-only symmetric float array; refuse non-finite or non-PSD."""
    out = np.array(matrix, dtype=float)
    if out.ndim < 2 or out.shape[-1] != out.shape[-2] or out.shape[-1] == 0:
        raise EstimationError(
            f"{owner}: {name} must have shape (..., k, k) with k >= 1, got {out.shape}"
        )
    if not np.isfinite(out).all():
        raise EstimationError(f"{owner}: {name} is not finite (NaN or inf)")
    out = symmetrise(out)
    if np.linalg.eigvalsh(out).min() < -1e-12 * max(1.0, float(np.abs(out).max())):
        raise EstimationError(f"{owner}: {name} is not positive semi-definite")
    out.flags.writeable = False
    return out


class ProcessNoise(StrEnum):
    """How the process noise ``w`` enters the transition."""

    ADDITIVE = "additive"
    """``x(k+1) = f(x(k), *args) + w(k)``."""
    AUGMENTED = "augmented"
    """``x(k+1) = f(x(k), w(k), *args)``: the UKF draws sigma points of the state augmented
    with ``w`` (paper 001 section III-C-2)."""


@dataclass(frozen=True)
class ProcessModel:
    """``x(k+1) = f(x(k), *args) + w(k)`` (additive) or ``f(x(k), w(k), *args)`` (augmented).

    Attributes:
        f: the transition, batched (see the module docstring).
        Q: ``(n, n)`` (additive) or ``(q, q)`` (augmented) noise covariance of ``w``, or a
            per-run ``(B, ., .)``; symmetric positive semi-definite.
        jacobian: ``F(x, *args) -> (..., n, n)``, needed by the EKF family (additive noise).
        noise: a :class:`ProcessNoise` (or its value), ``"additive"`` by default.
        noise_sqrt: computed, ``(..., q, q)`` a square root ``S S^T = Q`` (from the
            eigen-decomposition, so a singular ``Q`` is fine) for the augmented sigma points.
        point: optional per-point kernel computing ``f`` for one sigma point (module
            docstring); the UKF's compiled path.
        jacobian_point: optional per-point kernel computing ``jacobian`` for one state
            (module docstring); with ``point``, the EKF's compiled path.
    """

    f: Callable[..., np.ndarray]
    Q: np.ndarray
    jacobian: Callable[..., np.ndarray] | None = None
    noise: ProcessNoise = ProcessNoise.ADDITIVE
    point: Callable[..., None] | None = None
    jacobian_point: Callable[..., None] | None = None
    noise_sqrt: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not callable(self.f):
            raise EstimationError("ProcessModel: f must be callable")
        if self.jacobian is not None and not callable(self.jacobian):
            raise EstimationError("ProcessModel: jacobian must be callable or None")
        try:
            object.__setattr__(self, "noise", ProcessNoise(self.noise))
        except ValueError:
            allowed = ", ".join(repr(str(n)) for n in ProcessNoise)
            raise EstimationError(
                f"ProcessModel: noise must be one of {allowed}, got {self.noise!r}"
            ) from None
        _check_kernel("ProcessModel", self.point)
        _check_kernel("ProcessModel", self.jacobian_point, "jacobian_point")
        q_cov = _noise_covariance(self.Q, "ProcessModel", "Q")
        eigenvalues, eigenvectors = np.linalg.eigh(q_cov)
        noise_sqrt = eigenvectors * np.sqrt(np.maximum(eigenvalues, 0.0))[..., None, :]
        noise_sqrt.flags.writeable = False
        object.__setattr__(self, "Q", q_cov)
        object.__setattr__(self, "noise_sqrt", noise_sqrt)


@dataclass(frozen=True)
class MeasurementModel:
    """``z(k) = h(x(k), *args) + v(k)``, ``v ~ N(0, R)``.

    Attributes:
        h: the measurement function, batched.
        R: ``(m, m)`` (or per-run ``(B, m, m)``) noise covariance, symmetric PSD.
        jacobian: ``H(x, *args) -> (..., m, n)``, needed by the EKF family and the IUKF.
        angle_indices: the measurement components that are angles (residuals wrapped).
        point: optional per-point kernel computing ``h`` for one sigma point (module
            docstring); the UKF's compiled path.
        jacobian_point: optional per-point kernel computing ``jacobian`` for one state
            (module docstring); with ``point``, the EKF's compiled path.
    """

    h: Callable[..., np.ndarray]
    R: np.ndarray
    jacobian: Callable[..., np.ndarray] | None = None
    angle_indices: tuple[int, ...] = ()
    point: Callable[..., None] | None = None
    jacobian_point: Callable[..., None] | None = None

    def __post_init__(self) -> None:
        if not callable(self.h):
            raise EstimationError("MeasurementModel: h must be callable")
        _check_kernel("MeasurementModel", self.point)
        if self.jacobian is not None and not callable(self.jacobian):
            raise EstimationError("MeasurementModel: jacobian must be callable or None")
        _check_kernel("MeasurementModel", self.jacobian_point, "jacobian_point")
        R = _noise_covariance(self.R, "MeasurementModel", "R")
        m = R.shape[-1]
        angles = tuple(int(i) for i in self.angle_indices)
        if any(i < 0 or i >= m for i in angles) or len(set(angles)) != len(angles):
            raise EstimationError(
                f"MeasurementModel: angle_indices {self.angle_indices!r} must be distinct indices in [0, {m})"
            )
        object.__setattr__(self, "R", R)
        object.__setattr__(self, "angle_indices", angles)

    def residual(self, z: np.ndarray, z_pred: np.ndarray, step: str) -> np.ndarray:
        """``z - z_pred`` ``(..., m)``, angle components wrapped; refuses a ``z`` of the wrong shape."""
        if np.shape(z) != z_pred.shape:
            raise EstimationError(
                f"{step}: the measurement z has shape {np.shape(z)}, expected {z_pred.shape} (batch + (m,))"
            )
        return wrap_columns(z - z_pred, self.angle_indices)
