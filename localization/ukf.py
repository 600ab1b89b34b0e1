"""The unscented Kalman filter, additive or augmented process noise (papers 000, 001, 004).

Pure steps on immutable :class:`~localization.gaussian.Gaussian` beliefs, one run ``(n,)`` or a
batch ``(B, n)`` in one call::

    ukf = UnscentedKalmanFilter(points=ScaledSigmaPoints(alpha=1e-3))
    belief = ukf.predict(belief, process_model, u, dt_s)
    belief = ukf.update(belief, z, measurement_model)

Prediction (paper 001 eq. 25-27; paper 000 eq. 3-5; paper 004 eq. 3-6)::

    X = sigma points of (x, P)             [of (x, 0; P, 0; 0, Q) if augmented]
    Y_i = f(X_i, *args)                    [f(X_i^x, X_i^w, *args) if augmented]
    x- = sum Wm_i Y_i,  P- = sum Wc_i (Y_i - x-)(Y_i - x-)^T  (+ Q if additive)

Update (paper 001 eq. 29-35, paper 004 eq. 8-14; new sigma points are drawn from the predicted
belief, as in paper 004 eq. 8)::

    Z_i = h(X_i),  z- = sum Wm_i Z_i,  S = sum Wc_i (Z_i - z-)(Z_i - z-)^T + R
    Pxz = sum Wc_i (X_i - x-)(Z_i - z-)^T,  K = Pxz S^-1   (solved, never inverted)
    x+ = x- + K (z - z-),  P+ = P- - K S K^T = P- - Pxz K^T   (symmetrised)

(Paper 001 eq. 35 prints ``+ K U K^T``; the minus sign is the correct one.) The weighted sums
are taken about the centre sigma point (see :mod:`localization.sigma_points`), which keeps
paper 001's ``alpha = 1e-5`` exact. Angles declared in the belief and in the measurement
model are wrapped in every residual and mean.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from localization.errors import EstimationError
from localization.gaussian import Gaussian
from localization.linalg import PDPolicy, cholesky, require_finite, wrap_columns
from localization.models import MeasurementModel, ProcessModel
from localization.sigma_points import (
    ScaledSigmaPoints,
    SigmaPointScheme,
    cross_covariance,
    sigma_points,
    unscented_moments,
)


def at_sigma_points(args: tuple, batch_shape: tuple[int, ...]) -> tuple:
    """The step's arguments, per-run arrays given a sigma-point axis after the batch axes.

    An array whose leading axes equal ``batch_shape`` (non-empty) is per-run: ``(B,)`` becomes
    ``(B, 1)`` and ``(B, k)`` becomes ``(B, 1, k)``, so it broadcasts against the sigma points
    ``(B, 2n + 1, n)``. Everything else (floats, shared arrays) passes unchanged.
    """
    if not batch_shape:
        return args
    d = len(batch_shape)
    return tuple(
        np.expand_dims(a, d) if isinstance(a, np.ndarray) and a.shape[:d] == batch_shape else a for a in args
    )


def check_args(args: tuple, step: str) -> None:
    """Refuse non-finite step inputs (controls, time steps) with an :class:`EstimationError`."""
    for position, value in enumerate(args):
        if isinstance(value, float):
            if not math.isfinite(value):
                raise EstimationError(f"{step}: argument {position + 1} is not finite (NaN or inf)")
        elif isinstance(value, np.ndarray):
            require_finite(value, f"argument {position + 1}", step)


def kalman_correction(
    mean: np.ndarray, cov: np.ndarray, innovation: np.ndarray, cross_cov: np.ndarray, innovation_cov: np.ndarray,
    angle_indices: tuple[int, ...],
) -> tuple[np.ndarray, np.ndarray]:
    """``x + K y`` and ``P - Pxz K^T`` with ``K = Pxz S^-1`` from ``solve`` (shared by UKF variants).

    Shapes: ``mean (..., n)``, ``cov (..., n, n)``, ``innovation (..., m)``, ``cross_cov (..., n, m)``,
    ``innovation_cov (..., m, m)``.
    """
    gain_t = np.linalg.solve(innovation_cov, cross_cov.mT)  # K^T = S^-1 Pxz^T
    new_mean = wrap_columns(mean + (innovation[..., None, :] @ gain_t)[..., 0, :], angle_indices)
    new_cov = cov - cross_cov @ gain_t
    return new_mean, 0.5 * (new_cov + new_cov.mT)


@dataclass(frozen=True)
class UnscentedKalmanFilter:
    """UKF settings; ``predict`` and ``update`` are pure steps.

    Attributes:
        points: the sigma-point parametrisation (scaled, kappa or spread; see
            :mod:`localization.sigma_points`).
        pd_policy: what to do when a covariance to factorise is not positive definite.
    """

    points: SigmaPointScheme = field(default_factory=ScaledSigmaPoints)
    pd_policy: PDPolicy = field(default_factory=PDPolicy)

    def predict(self, belief: Gaussian, model: ProcessModel, *args) -> Gaussian:
        """The belief propagated one step through ``model`` (additive or augmented noise).

        Raises:
            EstimationError: non-finite ``args`` or result, or a covariance that is not
                positive definite under the ``"raise"`` policy.
        """
        check_args(args, "UKF predict")
        n = belief.mean.shape[-1]
        chol, _ = cholesky(belief.cov, self.pd_policy, "UKF predict")
        if model.noise == "additive":
            weights = self.points.weights(n)
            images = model.f(sigma_points(belief.mean, chol, weights), *at_sigma_points(args, belief.mean.shape[:-1]))
        else:
            q = model.Q.shape[-1]
            weights = self.points.weights(n + q)
            batch = belief.mean.shape[:-1]
            mean_aug = np.concatenate([belief.mean, np.zeros(batch + (q,))], axis=-1)
            chol_aug = np.zeros(batch + (n + q, n + q))  # a square root of blockdiag(P, Q)
            chol_aug[..., :n, :n] = chol
            chol_aug[..., n:, n:] = model.noise_sqrt
            points = sigma_points(mean_aug, chol_aug, weights)
            images = model.f(points[..., :n], points[..., n:], *at_sigma_points(args, batch))
        mean, cov, _ = unscented_moments(images, weights, belief.angle_indices)
        if model.noise == "additive":
            cov = cov + model.Q  # paper 004 eq. 6
        cov = 0.5 * (cov + cov.mT)
        require_finite(mean, "the predicted mean (model output)", "UKF predict")
        return Gaussian.trusted(mean, cov, belief.angle_indices)

    def update(self, belief: Gaussian, z: np.ndarray, model: MeasurementModel, *args) -> Gaussian:
        """The belief corrected by the measurement ``z (..., m)``.

        Raises:
            EstimationError: non-finite ``z``, ``args`` or result, or a covariance that is not
                positive definite under the ``"raise"`` policy.
        """
        require_finite(z, "the measurement z", "UKF update")
        check_args(args, "UKF update")
        weights = self.points.weights(belief.mean.shape[-1])
        chol, prior_cov = cholesky(belief.cov, self.pd_policy, "UKF update")
        points = sigma_points(belief.mean, chol, weights)
        z_pred, s_cov, dev_z = unscented_moments(
            model.h(points, *at_sigma_points(args, belief.mean.shape[:-1])), weights, model.angle_indices
        )
        mean, cov = kalman_correction(
            belief.mean,
            prior_cov,
            model.residual(z, z_pred, "UKF update"),
            cross_covariance(chol, dev_z, weights),
            s_cov + model.R,
            belief.angle_indices,
        )
        require_finite(mean, "the updated mean", "UKF update")
        return Gaussian.trusted(mean, cov, belief.angle_indices)

