"""The modified UKF and modified EKF of paper 004 section 3 (after Chui, Chen and Chui 1990).

For a state ``s = (x, y)`` with ``x`` (``n`` components) entering linearly::

    x(k+1) = F(y(k)) x(k) + xi_1(k),   y(k+1) = G(x(k), y(k)) + xi_2(k)     (eq. 15)
    z(k)   = H(x(k), y(k)) x(k) + eta(k)

two algorithms run in parallel from the same initial estimate:

- Algorithm I, a UKF (MUKF) or an EKF (MEKF) of the full state ``(x~, y~)`` with covariance
  ``P_I``, whose sigma points (MUKF) or linearisation point and propagated mean (MEKF) are
  taken at ``(x^(k-1), y~(k-1))``: the linear part comes from Algorithm II (eq. 18-20);
- Algorithm II, the linear Kalman filter of ``x`` for the subsystem (eq. 17, 21) with
  ``F(y~(k-1))`` and ``H(x~(k|k-1), y~(k|k-1))`` from Algorithm I, covariance ``P_II``.

The estimate of the pair is ``(x^(k), y~(k))``: the linear part from Algorithm II, the
parameters from Algorithm I (:attr:`ModifiedBelief.estimate`). The linear part carries no
angles.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from localization.ekf import ExtendedKalmanFilter, joseph_covariance, kalman_gain
from localization.errors import EstimationError
from localization.gaussian import Gaussian
from localization.linalg import require_finite, symmetrise
from localization.models import MeasurementModel, ProcessModel, ProcessNoise
from localization.ukf import UnscentedKalmanFilter, check_args


@dataclass(frozen=True)
class LinearSubsystem:
    """The linear part of eq. 15: the first ``n_linear`` state components.

    Attributes:
        n_linear: ``n``, the number of leading state components that enter linearly.
        transition: ``F(y (..., m), *args) -> (..., n, n)``.
        observation: ``H(x (..., n), y (..., m), *args) -> (..., p, n)``.
    """

    n_linear: int
    transition: Callable[..., np.ndarray]
    observation: Callable[..., np.ndarray]

    def __post_init__(self) -> None:
        if not (isinstance(self.n_linear, int) and self.n_linear >= 1):
            raise EstimationError(
                f"LinearSubsystem: n_linear must be an int >= 1, got {self.n_linear!r}"
            )
        if not (callable(self.transition) and callable(self.observation)):
            raise EstimationError("LinearSubsystem: transition and observation must be callable")


@dataclass(frozen=True)
class ModifiedBelief:
    """The pair of beliefs of the two parallel algorithms.

    Attributes:
        full: Algorithm I, ``(..., n + m)`` mean ``(x~, y~)`` and its covariance ``P_I``.
        linear: Algorithm II, ``(..., n)`` mean ``x^`` and its covariance ``P_II``.
    """

    full: Gaussian
    linear: Gaussian

    @property
    def estimate(self) -> np.ndarray:
        """``(..., n + m)`` the filter's estimate ``(x^, y~)``."""
        n = self.linear.mean.shape[-1]
        return np.concatenate([self.linear.mean, self.full.mean[..., n:]], axis=-1)


@dataclass(frozen=True)
class ModifiedKalmanFilter:
    """MUKF (``inner`` a UKF) or MEKF (``inner`` an EKF), paper 004 section 3.

    Attributes:
        inner: the nonlinear filter of Algorithm I.
        subsystem: the linear part used by Algorithm II.
    """

    inner: UnscentedKalmanFilter | ExtendedKalmanFilter
    subsystem: LinearSubsystem

    def __post_init__(self) -> None:
        if not isinstance(self.inner, (UnscentedKalmanFilter, ExtendedKalmanFilter)):
            raise EstimationError(
                "ModifiedKalmanFilter: inner must be an UnscentedKalmanFilter or ExtendedKalmanFilter"
            )
        if not isinstance(self.subsystem, LinearSubsystem):
            raise EstimationError("ModifiedKalmanFilter: subsystem must be a LinearSubsystem")

    @property
    def name(self) -> str:
        """``"MUKF"`` or ``"MEKF"``."""
        return "MUKF" if isinstance(self.inner, UnscentedKalmanFilter) else "MEKF"

    def initial(self, belief: Gaussian) -> ModifiedBelief:
        """Both algorithms start from ``belief`` (Algorithm II from its linear block)."""
        n = self.subsystem.n_linear
        if belief.dim <= n:
            raise EstimationError(
                f"{self.name}: the state must have more than n_linear = {n} components"
            )
        if any(i < n for i in belief.angle_indices):
            raise EstimationError(f"{self.name}: the linear components cannot be angles")
        return ModifiedBelief(
            belief, Gaussian.trusted(belief.mean[..., :n], belief.cov[..., :n, :n], ())
        )

    def predict(self, belief: ModifiedBelief, model: ProcessModel, *args) -> ModifiedBelief:
        """Algorithm I prediction about ``(x^(k-1), y~(k-1))``; Algorithm II with ``F(y~(k-1))`` (eq. 21).

        Raises:
            EstimationError: non-finite inputs, augmented noise, or an inner-filter failure.
        """
        step = f"{self.name} predict"
        check_args(args, step)
        if model.noise != ProcessNoise.ADDITIVE:
            raise EstimationError(f"{step}: the modified filters need additive process noise")
        n = self.subsystem.n_linear
        full = belief.full
        recentred = Gaussian.trusted(belief.estimate, full.cov, full.angle_indices)  # eq. 18
        full_pred = self.inner.predict(recentred, model, *args)
        transition = self.subsystem.transition(full.mean[..., n:], *args)  # F(y~(k-1))
        mean = (transition @ belief.linear.mean[..., None])[..., 0]
        cov = transition @ belief.linear.cov @ transition.mT + model.Q[..., :n, :n]
        require_finite(mean, "the predicted linear mean", step)
        return ModifiedBelief(full_pred, Gaussian.trusted(mean, symmetrise(cov), ()))

    def update(
        self, belief: ModifiedBelief, z: np.ndarray, model: MeasurementModel, *args
    ) -> ModifiedBelief:
        """Algorithm I update; Algorithm II with ``H(x~(k|k-1), y~(k|k-1))`` (eq. 21).

        Raises:
            EstimationError: non-finite inputs or an inner-filter failure.
        """
        step = f"{self.name} update"
        require_finite(z, "the measurement z", step)
        n = self.subsystem.n_linear
        predicted = belief.full.mean
        observation = self.subsystem.observation(predicted[..., :n], predicted[..., n:], *args)
        full_upd = self.inner.update(belief.full, z, model, *args)
        linear = belief.linear
        gain = kalman_gain(linear.cov, observation, model.R)
        innovation = (
            np.asarray(z, dtype=float) - (observation @ linear.mean[..., None])[..., 0]
        )  # no angles
        mean = linear.mean + (gain @ innovation[..., None])[..., 0]
        cov = joseph_covariance(linear.cov, gain, observation, model.R)
        return ModifiedBelief(full_upd, Gaussian.trusted(mean, cov, ()))
