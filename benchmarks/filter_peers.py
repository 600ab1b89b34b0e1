"""The peer filters of ``filters.py``, each set up as its own documentation shows a user.

Nothing here calls the project's model functions: each peer gets the CTRV model written the
way a user of that library would write it, in the textbook form ``x + v/omega (sin(theta +
omega T) - sin theta)`` (paper 001 eq. 5), with its Jacobian derived by hand.

- filterpy (``UnscentedKalmanFilter``, ``ExtendedKalmanFilter``): callbacks on one state in
  plain ``math`` on floats, returning a small numpy array; the heading either wrapped (the
  user's own residual, mean and add functions, as filterpy's documentation asks for angles) or
  continuous (filterpy's defaults on an unwrapped heading).
- Stone Soup (``UnscentedKalmanPredictor``/``Updater``, ``ExtendedKalmanPredictor``/``Updater``):
  a ``GaussianTransitionModel`` subclass vectorised over the columns of ``StateVectors`` (as
  Stone Soup's own ``ConstantTurn``), the pose measured by its ``LinearGaussian`` model;
  heading continuous (Stone Soup's angle types use a different circular mean, so the estimates
  would not be comparable to ours).

Every runner takes one run ``z (steps, 3)`` and ``initial (5,)`` and returns the means
``(steps, 5)`` and covariances ``(steps, 5, 5)`` after each update.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from datetime import datetime, timedelta

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter as FilterpyEKF
from filterpy.kalman import MerweScaledSigmaPoints
from filterpy.kalman import UnscentedKalmanFilter as FilterpyUKF
from stonesoup.base import Property
from stonesoup.models.base import TimeVariantModel
from stonesoup.models.measurement.linear import LinearGaussian
from stonesoup.models.transition.nonlinear import GaussianTransitionModel
from stonesoup.predictor.kalman import ExtendedKalmanPredictor, UnscentedKalmanPredictor
from stonesoup.types.array import CovarianceMatrix, StateVector, StateVectors
from stonesoup.types.detection import Detection
from stonesoup.types.hypothesis import SingleHypothesis
from stonesoup.types.state import GaussianState
from stonesoup.updater.kalman import ExtendedKalmanUpdater, UnscentedKalmanUpdater

TWO_PI = 2.0 * math.pi
HEADING = 2
H_POSE = np.eye(3, 5)
"""``(3, 5)``: the pose measurement ``(x_m, y_m, theta_rad)`` is linear in the state."""


@dataclass(frozen=True)
class Problem:
    """The tracking problem's constants, set in ``filters.py``."""

    dt_s: float
    Q: np.ndarray  # (5, 5) process noise per step
    R: np.ndarray  # (3, 3) measurement noise: m^2, m^2, rad^2
    P0: np.ndarray  # (5, 5) initial covariance
    alpha: float  # scaled sigma points (van der Merwe)
    beta: float
    kappa: float


# ------------------------------------------------------------------ filterpy: one state


def wrap(angle: float) -> float:
    """An angle in rad wrapped to ``[-pi, pi)``."""
    return (angle + math.pi) % TWO_PI - math.pi


def ctrv_fx(x: np.ndarray, dt: float, wrapped: bool = True) -> np.ndarray:
    """CTRV of one state ``(x_m, y_m, theta_rad, v_m_s, omega_rad_s)`` over ``dt`` s."""
    px, py, theta, v, omega = x
    theta_new = theta + omega * dt
    if abs(omega) > 1e-9:
        r = v / omega  # turn radius (m), signed
        px, py = (
            px + r * (math.sin(theta_new) - math.sin(theta)),
            py + r * (math.cos(theta) - math.cos(theta_new)),
        )
    else:
        px, py = px + v * dt * math.cos(theta), py + v * dt * math.sin(theta)
    return np.array([px, py, wrap(theta_new) if wrapped else theta_new, v, omega])


def ctrv_F(x: np.ndarray, dt: float) -> np.ndarray:
    """``(5, 5)`` Jacobian of :func:`ctrv_fx` at one state: that of its turning branch
    (``|omega| > 1e-9``), the one the filters meet."""
    _, _, theta, v, omega = x
    s0, c0 = math.sin(theta), math.cos(theta)
    s1, c1 = math.sin(theta + omega * dt), math.cos(theta + omega * dt)
    r = v / omega
    return np.array(
        [
            [1.0, 0.0, r * (c1 - c0), (s1 - s0) / omega, -r / omega * (s1 - s0) + r * dt * c1],
            [0.0, 1.0, r * (s1 - s0), (c0 - c1) / omega, -r / omega * (c0 - c1) + r * dt * s1],
            [0.0, 0.0, 1.0, 0.0, dt],
            [0.0, 0.0, 0.0, 1.0, 0.0],
            [0.0, 0.0, 0.0, 0.0, 1.0],
        ]
    )


def hx(x: np.ndarray) -> np.ndarray:
    """The pose ``(3,)`` of one state."""
    return x[:3]


def H_of(x: np.ndarray) -> np.ndarray:
    """Jacobian of :func:`hx` (a constant)."""
    return H_POSE


def heading_residual(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a - b`` with the heading (index 2, in the state and in the measurement) wrapped."""
    d = a - b
    d[HEADING] = wrap(d[HEADING])
    return d


def heading_add(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a + b`` with the heading wrapped."""
    s = a + b
    s[HEADING] = wrap(s[HEADING])
    return s


def heading_mean(sigmas: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Weighted mean of sigma points ``(11, m)``, the heading as wrapped offsets about the
    centre point (the definition ours uses; ``sum W_i X_i`` when nothing wraps)."""
    offsets = sigmas - sigmas[0]
    offsets[:, HEADING] = (offsets[:, HEADING] + math.pi) % TWO_PI - math.pi
    mean = sigmas[0] + weights @ offsets
    mean[HEADING] = wrap(mean[HEADING])
    return mean


def filterpy_ukf_run(p: Problem, z, initial, wrapped: bool = True):
    """filterpy's UKF over one run; ``wrapped``: the heading wrapped by the user's own
    residual, mean and add functions, else continuous with filterpy's defaults."""
    angle_fns = (
        {
            "x_mean_fn": heading_mean,
            "z_mean_fn": heading_mean,
            "residual_x": heading_residual,
            "residual_z": heading_residual,
            "state_add": heading_add,
        }
        if wrapped
        else {}
    )
    ukf = FilterpyUKF(
        dim_x=5,
        dim_z=3,
        dt=p.dt_s,
        hx=hx,
        fx=lambda x, dt: ctrv_fx(x, dt, wrapped),
        points=MerweScaledSigmaPoints(5, alpha=p.alpha, beta=p.beta, kappa=p.kappa),
        **angle_fns,
    )
    ukf.x, ukf.P, ukf.Q, ukf.R = initial.copy(), p.P0.copy(), p.Q.copy(), p.R.copy()
    means, covs = np.empty((len(z), 5)), np.empty((len(z), 5, 5))
    for k, zk in enumerate(z):
        ukf.predict()
        ukf.update(zk)
        means[k], covs[k] = ukf.x, ukf.P
    return means, covs


class _CTRVFilterpyEKF(FilterpyEKF):
    """filterpy's EKF with a nonlinear transition through ``predict_x`` (its documented hook)."""

    x: np.ndarray  # (5,) the state mean, filterpy's attribute

    def __init__(self, dt_s: float, wrapped: bool):
        super().__init__(dim_x=5, dim_z=3)
        self.dt_s, self.wrapped = dt_s, wrapped

    def predict_x(self, u=0):
        self.x = ctrv_fx(self.x, self.dt_s, self.wrapped)


def filterpy_ekf_run(p: Problem, z, initial, wrapped: bool = True):
    """filterpy's EKF over one run, ``F`` set to the CTRV Jacobian before each predict;
    ``wrapped``: the innovation's heading wrapped by the user's residual function."""
    ekf = _CTRVFilterpyEKF(p.dt_s, wrapped)
    ekf.x, ekf.P, ekf.Q, ekf.R = initial.copy(), p.P0.copy(), p.Q.copy(), p.R.copy()
    residual = heading_residual if wrapped else np.subtract
    means, covs = np.empty((len(z), 5)), np.empty((len(z), 5, 5))
    for k, zk in enumerate(z):
        ekf.F = ctrv_F(ekf.x, p.dt_s)
        ekf.predict()
        ekf.update(zk, H_of, hx, residual=residual)
        if wrapped:
            ekf.x[HEADING] = wrap(ekf.x[HEADING])
        means[k], covs[k] = ekf.x, ekf.P
    return means, covs


# ------------------------------------------------------- Stone Soup: columns of states


class CTRVTransition(GaussianTransitionModel, TimeVariantModel):
    """CTRV as a Stone Soup transition model (heading continuous), additive noise ``Q`` per
    step of the problem's ``dt``."""

    noise_covar: CovarianceMatrix = Property(doc="Process noise per step, (5, 5)")

    @property
    def ndim_state(self):
        return 5

    def function(self, state, noise=False, **kwargs):
        dt = kwargs["time_interval"].total_seconds()
        px, py, theta, v, omega = np.asarray(state.state_vector, dtype=float)
        theta_new = theta + omega * dt
        r = v / omega
        moved = StateVectors(
            [
                px + r * (np.sin(theta_new) - np.sin(theta)),
                py + r * (np.cos(theta) - np.cos(theta_new)),
                theta_new,
                v,
                omega,
            ]
        )
        if isinstance(noise, bool) or noise is None:
            noise = self.rvs(num_samples=moved.shape[1], **kwargs) if noise else 0
        return moved + noise

    def jacobian(self, state, **kwargs):
        dt = kwargs["time_interval"].total_seconds()
        return ctrv_F(np.asarray(state.state_vector, dtype=float).ravel(), dt)

    def covar(self, **kwargs):
        return self.noise_covar


def _stonesoup_run(p: Problem, z, initial, predictor, updater, measurement):
    start = datetime(2026, 1, 1)
    step = timedelta(seconds=p.dt_s)
    state = GaussianState(StateVector(initial), CovarianceMatrix(p.P0), timestamp=start)
    means, covs = np.empty((len(z), 5)), np.empty((len(z), 5, 5))
    for k, zk in enumerate(z):
        t = start + (k + 1) * step
        prediction = predictor.predict(state, timestamp=t)
        detection = Detection(StateVector(zk), timestamp=t, measurement_model=measurement)
        state = updater.update(SingleHypothesis(prediction, detection))
        means[k], covs[k] = np.ravel(state.state_vector), state.covar
    return means, covs


def _stonesoup_models(p: Problem):
    return CTRVTransition(noise_covar=CovarianceMatrix(p.Q)), LinearGaussian(
        ndim_state=5, mapping=(0, 1, 2), noise_covar=CovarianceMatrix(p.R)
    )


def stonesoup_ukf_run(p: Problem, z, initial):
    """Stone Soup's UKF over one run (heading continuous: ``z`` unwrapped)."""
    transition, measurement = _stonesoup_models(p)
    spread = {"alpha": p.alpha, "beta": p.beta, "kappa": p.kappa}
    predictor = UnscentedKalmanPredictor(transition, **spread)
    updater = UnscentedKalmanUpdater(measurement, **spread)
    return _stonesoup_run(p, z, initial, predictor, updater, measurement)


def stonesoup_ekf_run(p: Problem, z, initial):
    """Stone Soup's EKF over one run (heading continuous: ``z`` unwrapped)."""
    transition, measurement = _stonesoup_models(p)
    predictor = ExtendedKalmanPredictor(transition)
    updater = ExtendedKalmanUpdater(measurement)
    return _stonesoup_run(p, z, initial, predictor, updater, measurement)
