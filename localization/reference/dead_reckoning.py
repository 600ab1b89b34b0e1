"""The dead reckoning by the generic filter classes, the reference of its compiled step.

:class:`GenericDeadReckoning` is :class:`localization.dead_reckoning.DeadReckoning` with each
step run by ``UnscentedKalmanFilter``, ``IteratedUnscentedKalmanFilter``,
``ExtendedKalmanFilter`` or ``IteratedExtendedKalmanFilter`` of :mod:`localization` on the
batched model below (the numpy statement of the model of the module doc of
:mod:`localization.dead_reckoning`), about a hundred times slower than the compiled step of
:mod:`localization.compiled.dead_reckoning`, which the tests compare with it. Tests and
benchmarks only: the production path never imports this module.
"""

from __future__ import annotations

import numpy as np

from localization.compiled.dead_reckoning import B_GYRO, D_WHEEL, N_STATES, OMEGA, V
from localization.dead_reckoning import (
    ANGLE_INDICES,
    DeadReckoning,
    DeadReckoningSettings,
    Filter,
    OdometryData,
    transition,
    transition_jacobian,
)
from localization.ekf import ExtendedKalmanFilter, IteratedExtendedKalmanFilter
from localization.gaussian import Gaussian
from localization.iukf import IteratedUnscentedKalmanFilter
from localization.models import MeasurementModel, ProcessModel
from localization.ukf import UnscentedKalmanFilter


def measurement_matrix(regressor: np.ndarray, wheel_base_m: float) -> np.ndarray:
    """``H (..., 3, 8)`` of ``(v_enc, omega_enc, gyro)``: the products ``omega d_wheel`` and
    ``v d_wheel`` with ``omega`` and ``v`` taken from ``regressor (..., 8)``, an estimate made
    before the step's encoder data: the filter passes the predicted state with the speed
    predicted from two steps back (module docstring)."""
    h_matrix = np.zeros(regressor.shape[:-1] + (3, N_STATES))
    h_matrix[..., 0, V] = 1.0
    h_matrix[..., 0, D_WHEEL] = -0.25 * wheel_base_m * regressor[..., OMEGA]
    h_matrix[..., 1, OMEGA] = 1.0
    h_matrix[..., 1, D_WHEEL] = -regressor[..., V] / wheel_base_m
    h_matrix[..., 2, OMEGA] = 1.0
    h_matrix[..., 2, B_GYRO] = 1.0
    return h_matrix


def measure(state: np.ndarray, h_matrix: np.ndarray) -> np.ndarray:
    """``h(s) = H s`` ``(..., 3)`` = predicted ``(v_enc, omega_enc, gyro)``; ``h_matrix (..., 3, 8)``."""
    return (h_matrix @ state[..., None])[..., 0]


def measure_jacobian(state: np.ndarray, h_matrix: np.ndarray) -> np.ndarray:
    """``dh/ds = H``, broadcast to ``(..., 3, 8)``."""
    return np.broadcast_to(h_matrix, np.broadcast_shapes(state.shape[:-1] + (1, 1), h_matrix.shape))


def process_model(data: OdometryData) -> ProcessModel:
    """The motion model as the generic filter classes consume it (additive noise ``data.Q``,
    with its Jacobian)."""
    return ProcessModel(transition, data.Q, jacobian=transition_jacobian)


def measurement_model(data: OdometryData) -> MeasurementModel:
    """``z = H(k) s + v`` with the noise ``data.R``; the step passes ``H(k)``
    (:func:`measurement_matrix`) as the argument of ``h``."""
    return MeasurementModel(measure, data.R, jacobian=measure_jacobian)


def generic_filter(settings: DeadReckoningSettings):
    """The generic filter object for ``settings`` (its filter and sigma points)."""
    if settings.filter == Filter.UKF:
        return UnscentedKalmanFilter(points=settings.sigma_points())
    if settings.filter == Filter.IUKF:
        return IteratedUnscentedKalmanFilter(points=settings.sigma_points())
    if settings.filter == Filter.EKF:
        return ExtendedKalmanFilter()
    return IteratedExtendedKalmanFilter()


def innovation_nis(
    predicted: Gaussian, z: np.ndarray, h: np.ndarray, r_cov: np.ndarray
) -> np.ndarray:
    """``(B,)`` the NIS ``nu^T S^-1 nu`` of the linear update of ``predicted (B, 8)`` by
    ``z (B, 3)`` with ``h (B, 3, 8)``: ``nu = z - H x-``, ``S = H P- H^T + R``."""
    nu = z - np.einsum("bij,bj->bi", h, predicted.mean)
    s_cov = h @ predicted.cov @ h.mT + r_cov
    return np.einsum("bi,bi->b", nu, np.linalg.solve(s_cov, nu[..., None])[..., 0])


class GenericDeadReckoning(DeadReckoning):
    """:class:`~localization.dead_reckoning.DeadReckoning` (same arguments, same history and
    refusals of bad calls) whose steps run the generic filter for its settings, one sample at
    a time."""

    def __init__(
        self,
        data: OdometryData,
        initial: Gaussian,
        settings: DeadReckoningSettings,
        record_full_cov: bool = False,
    ) -> None:
        super().__init__(data, initial, settings, record_full_cov)
        self._generic = generic_filter(settings)
        self._process = process_model(data)
        self._measurement = measurement_model(data)

    def _steps(self, start: int, stop: int) -> None:
        data, filt = self.data, self._generic
        batch = self._mean.shape[0]
        belief = Gaussian.trusted(self._mean, self._cov, ANGLE_INDICES)
        for k in range(start, stop):
            accel = data.accel_input_m_s2[k]
            accel = accel if data.per_run else np.full(batch, accel)
            z = np.broadcast_to(data.z[k], (batch, 3))
            predicted = filt.predict(belief, self._process, accel, data.dt_s)
            regressor = np.array(predicted.mean)
            regressor[:, V] -= self._speed_correction
            h = measurement_matrix(regressor, data.wheel_base_m)
            self._nis_hist[k] = innovation_nis(predicted, z, h, data.R)
            belief = filt.update(predicted, z, self._measurement, h)
            self._speed_correction = belief.mean[:, V] - predicted.mean[:, V]
            self._mean, self._cov = belief.mean, belief.cov
            self._record(k)
