"""The extended Kalman filter and the iterated EKF (Gauss-Newton on the measurement).

EKF (additive noise; ``F``, ``H`` the Jacobians of the models)::

    predict:  x- = f(x, *args),  P- = F P F^T + Q
    update:   y = z - h(x-),  S = H P- H^T + R,  K = P- H^T S^-1   (solved)
              x+ = x- + K y,  P+ = (I - K H) P- (I - K H)^T + K R K^T   (Joseph form)

Iterated update (paper 000 eq. 7-12; Bell and Cathey): Newton/Gauss-Newton on
``f(x) = 1/2 |x - x-|^2_{P-^-1} + 1/2 |z - h(x)|^2_{R^-1}`` from ``x_0 = x-``. Eq. 11 is used in
its gain form, equal by the matrix inversion lemma and free of ``P-^-1``::

    H_l = H(x_{l-1}),  K_l = P- H_l^T (H_l P- H_l^T + R)^-1
    x_l = x- + K_l (z - h(x_{l-1}) - H_l (x- - x_{l-1}))          (eq. 11)
    P+  = (P-^-1 + H_l^T R^-1 H_l)^-1 = (I - K_l H_l) P-           (eq. 12, Joseph form)

With one iteration this is the EKF update. Iterations stop per run when
``max |x_l - x_{l-1}| <= tolerance (1 + max |x_l|)`` (the converged runs of a batch are frozen, so a batch gives
the runs' own numbers), or at ``max_iterations`` with a :class:`ConvergenceWarning`.

Two paths. When a model carries per-point kernels of its function and of its Jacobian
(``point=`` and ``jacobian_point=``, e.g. the models built by ``CTRV.process_model(Q)``,
:func:`~localization.motion_models.pose_model`), has additive noise, and the step can be
expressed there (a flat batch or one run, arguments that are numbers), the EKF's predict and
update and the IEKF's predict run compiled (:mod:`localization.compiled.ekf`: one call per step,
the same maths, equal to rounding; about ten times faster for one CTRV filter). Otherwise, and
whenever the compiled step declines (non-finite input or result, ``S`` not positive definite),
the numpy path below takes the step; it is the reference and raises the errors. The IEKF's
update stays numpy.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from localization.compiled import ekf as compiled_ekf
from localization.errors import EstimationError
from localization.gaussian import Gaussian
from localization.linalg import ConvergenceWarning, require_finite, wrap_columns
from localization.models import MeasurementModel, ProcessModel, ProcessNoise
from localization.ukf import check_args


def compiled_path(model: ProcessModel | MeasurementModel) -> bool:
    """Whether a step with ``model`` may take the compiled path (both kernels and the numpy
    Jacobian, the reference, are there)."""
    return (
        model.jacobian_point is not None and model.point is not None and model.jacobian is not None
    )


def _jacobian_of(model: ProcessModel | MeasurementModel, step: str) -> Callable[..., np.ndarray]:
    """The model's Jacobian function; an :class:`EstimationError` when it has none."""
    if model.jacobian is None:
        raise EstimationError(f"{step}: the model has no jacobian (the EKF family needs one)")
    return model.jacobian


def ekf_predict(belief: Gaussian, model: ProcessModel, args: tuple, step: str) -> Gaussian:
    """``x- = f(x)``, ``P- = F P F^T + Q`` (additive noise only)."""
    if compiled_path(model) and model.noise == ProcessNoise.ADDITIVE:
        done = compiled_ekf.predict(belief.mean, belief.cov, belief.angle_indices, model, args)
        if done is not None:
            return Gaussian.trusted(*done, belief.angle_indices)
    check_args(args, step)
    jacobian = _jacobian_of(model, step)
    if model.noise != ProcessNoise.ADDITIVE:
        raise EstimationError(f"{step}: the EKF family needs additive process noise")
    jac = jacobian(belief.mean, *args)
    mean = wrap_columns(np.array(model.f(belief.mean, *args), dtype=float), belief.angle_indices)
    cov = jac @ belief.cov @ jac.mT + model.Q
    require_finite(mean, "the predicted mean (model output)", step)
    return Gaussian.trusted(mean, 0.5 * (cov + cov.mT), belief.angle_indices)


def kalman_gain(cov: np.ndarray, jac: np.ndarray, r_cov: np.ndarray) -> np.ndarray:
    """``K = P H^T (H P H^T + R)^-1`` ``(..., n, m)`` by ``solve`` (``H = jac (..., m, n)``)."""
    cross = cov @ jac.mT  # P H^T
    return np.swapaxes(np.linalg.solve(jac @ cross + r_cov, cross.mT), -1, -2)


def joseph_covariance(
    cov: np.ndarray, gain: np.ndarray, jac: np.ndarray, r_cov: np.ndarray
) -> np.ndarray:
    """``(I - K H) P (I - K H)^T + K R K^T`` (symmetrised), positive definite by construction."""
    a = np.eye(cov.shape[-1]) - gain @ jac
    new_cov = a @ cov @ a.mT + gain @ r_cov @ gain.mT
    return 0.5 * (new_cov + new_cov.mT)


@dataclass(frozen=True)
class ExtendedKalmanFilter:
    """The EKF; ``predict`` and ``update`` are pure steps on :class:`Gaussian` beliefs."""

    def predict(self, belief: Gaussian, model: ProcessModel, *args) -> Gaussian:
        """``x- = f(x, *args)``, ``P- = F P F^T + Q``.

        Raises:
            EstimationError: no Jacobian, augmented noise, or non-finite inputs or result.
        """
        return ekf_predict(belief, model, args, "EKF predict")

    def update(self, belief: Gaussian, z: np.ndarray, model: MeasurementModel, *args) -> Gaussian:
        """The belief corrected by ``z (..., m)`` (Joseph form).

        Raises:
            EstimationError: no Jacobian, non-finite ``z``, ``args`` or result.
        """
        if compiled_path(model):
            done = compiled_ekf.update(
                belief.mean, belief.cov, belief.angle_indices, z, model, args
            )
            if done is not None:
                return Gaussian.trusted(*done, belief.angle_indices)
        step = "EKF update"
        require_finite(z, "the measurement z", step)
        check_args(args, step)
        jacobian = _jacobian_of(model, step)
        innovation = model.residual(z, model.h(belief.mean, *args), step)
        jac = jacobian(belief.mean, *args)
        gain = kalman_gain(belief.cov, jac, model.R)
        mean = wrap_columns(
            belief.mean + (gain @ innovation[..., None])[..., 0], belief.angle_indices
        )
        cov = joseph_covariance(belief.cov, gain, jac, model.R)
        require_finite(mean, "the updated mean", step)
        return Gaussian.trusted(mean, cov, belief.angle_indices)


@dataclass(frozen=True)
class IterationSettings:
    """Stopping rule of an iterated update.

    Attributes:
        max_iterations: the iteration cap ``L >= 1`` (paper 000 fixes ``L``).
        tolerance: stop a run when ``max |x_l - x_{l-1}| <= tolerance (1 + max |x_l|)`` (absolute
            near zero, relative for large states);
            ``None`` runs exactly ``max_iterations`` iterations and never warns.
    """

    max_iterations: int = 10
    tolerance: float | None = 1e-9

    def __post_init__(self) -> None:
        if not (isinstance(self.max_iterations, int) and self.max_iterations >= 1):
            raise EstimationError(
                f"IterationSettings: max_iterations must be an int >= 1, got {self.max_iterations!r}"
            )
        if self.tolerance is not None and not (
            math.isfinite(self.tolerance) and self.tolerance > 0.0
        ):
            raise EstimationError(
                f"IterationSettings: tolerance must be finite and > 0 or None, got {self.tolerance!r}"
            )


def iterated_update(
    belief: Gaussian,
    z: np.ndarray,
    model: MeasurementModel,
    args: tuple,
    settings: IterationSettings,
    step: str,
) -> Gaussian:
    """The Gauss-Newton measurement update of paper 000 eq. 11-12 (see the module docstring).

    Raises:
        EstimationError: no Jacobian, non-finite ``z``, ``args`` or result.

    Warns:
        ConvergenceWarning: some runs did not meet the tolerance within ``max_iterations``.
    """
    require_finite(z, "the measurement z", step)
    check_args(args, step)
    jacobian = _jacobian_of(model, step)
    angles = belief.angle_indices
    prior = belief.mean
    iterate = prior
    active = np.ones(prior.shape[:-1], dtype=bool)
    gain = jac = None
    for _ in range(settings.max_iterations):
        jac_l = jacobian(iterate, *args)
        innovation = model.residual(z, model.h(iterate, *args), step)
        correction = innovation - (jac_l @ wrap_columns(prior - iterate, angles)[..., None])[..., 0]
        gain_l = kalman_gain(belief.cov, jac_l, model.R)
        new_iterate = wrap_columns(prior + (gain_l @ correction[..., None])[..., 0], angles)
        step_size = np.abs(wrap_columns(new_iterate - iterate, angles)).max(axis=-1)
        mask = active[..., None]
        iterate = np.where(mask, new_iterate, iterate)
        gain = gain_l if gain is None else np.where(mask[..., None], gain_l, gain)
        jac = jac_l if jac is None else np.where(mask[..., None], jac_l, jac)
        if settings.tolerance is not None:
            active = active & (
                step_size > settings.tolerance * (1.0 + np.abs(new_iterate).max(axis=-1))
            )
            if not active.any():
                break
    if settings.tolerance is not None and active.any():
        warnings.warn(
            ConvergenceWarning(
                f"{step}: {int(active.sum())} run(s) did not converge to tolerance {settings.tolerance:g} "
                f"within {settings.max_iterations} iterations"
            ),
            stacklevel=3,
        )
    require_finite(iterate, "the updated mean", step)
    assert gain is not None and jac is not None  # IterationSettings: max_iterations >= 1
    return Gaussian.trusted(iterate, joseph_covariance(belief.cov, gain, jac, model.R), angles)


@dataclass(frozen=True)
class IteratedExtendedKalmanFilter:
    """The iterated EKF: EKF prediction, Gauss-Newton update (paper 000 eq. 11-12).

    Attributes:
        iteration: the iteration cap and tolerance.
    """

    iteration: IterationSettings = field(default_factory=IterationSettings)

    def predict(self, belief: Gaussian, model: ProcessModel, *args) -> Gaussian:
        """Same as :meth:`ExtendedKalmanFilter.predict`."""
        return ekf_predict(belief, model, args, "IEKF predict")

    def update(self, belief: Gaussian, z: np.ndarray, model: MeasurementModel, *args) -> Gaussian:
        """The iterated (Gauss-Newton) update; see :func:`iterated_update`."""
        return iterated_update(belief, z, model, args, self.iteration, "IEKF update")
