"""Our UKF and EKF give filterpy's estimates on a CTRV problem whose heading crosses +-pi.

filterpy is an independent implementation (sigma points from ``scipy.linalg.cholesky``, weighted
sums over all points, an explicit inverse of ``S``); with the same model, noise, sigma-point
parameters and angle handling both must agree to rounding. filterpy is in the ``test`` extra.
"""

from __future__ import annotations

import numpy as np
import pytest
from filterpy import kalman as filterpy_kalman

from localization.ekf import ExtendedKalmanFilter
from localization.gaussian import Gaussian
from localization.linalg import wrap_angle
from localization.models import MeasurementModel, ProcessModel
from localization.motion_models import CTRV, pose_model
from localization.sigma_points import ScaledSigmaPoints
from localization.ukf import UnscentedKalmanFilter

DT_S = 0.1
Q = np.diag([1e-4, 1e-4, 1e-4, 0.05, 0.01])
R = np.diag([0.09, 0.09, 0.01])
P0 = np.diag([0.25, 0.25, 0.05, 0.25, 0.01])
H = np.eye(3, 5)


def _wrap_heading(v: np.ndarray) -> np.ndarray:
    v = np.array(v, dtype=float)
    v[..., 2] = wrap_angle(v[..., 2])
    return v


def _residual(a, b):
    return _wrap_heading(np.subtract(a, b))


def _mean_about_centre(sigmas, weights):
    offsets = _wrap_heading(sigmas - sigmas[0])
    return _wrap_heading(sigmas[0] + weights @ offsets)


class _NonlinearEKF(filterpy_kalman.ExtendedKalmanFilter):
    def predict_x(self, u=0):
        self.x = CTRV.transition(self.x, DT_S)


@pytest.fixture(scope="module")
def data():
    """Start heading near +pi, turning left: the heading wraps within a few steps."""
    rng = np.random.default_rng(7)
    x = np.array([0.0, 0.0, 3.05, 2.0, 0.8])
    start = _wrap_heading(x + rng.normal(size=5) * np.sqrt(np.diag(P0)))
    zs = []
    for _ in range(60):
        x = _wrap_heading(CTRV.transition(x, DT_S) + rng.normal(size=5) * np.sqrt(np.diag(Q)))
        zs.append(_wrap_heading(x[:3] + rng.normal(size=3) * np.sqrt(np.diag(R))))
    return start, np.array(zs)


def _ours(filt, start, zs, compiled=False):
    if compiled:  # the models with their kernels: the UKF's compiled path
        process, measurement = CTRV.process_model(Q), pose_model(R)
    else:
        process = ProcessModel(CTRV.transition, Q, jacobian=CTRV.jacobian)
        measurement = MeasurementModel(
            lambda x: x[..., :3], R, jacobian=lambda x: H, angle_indices=(2,)
        )
    belief = Gaussian(start, P0, angle_indices=(2,))
    out = []
    for z in zs:
        belief = filt.update(filt.predict(belief, process, DT_S), z, measurement)
        out.append((belief.mean, belief.cov))
    return out


def _assert_same(ours, theirs):
    headings = np.array([m[2] for m, _ in ours])
    assert headings.max() > 2.5 and headings.min() < -2.5, (
        "the heading must cross +-pi in this test"
    )
    for (m, p), (fm, fp) in zip(ours, theirs, strict=True):
        np.testing.assert_allclose(_residual(m, fm), 0.0, atol=1e-10)
        np.testing.assert_allclose(p, fp, rtol=0, atol=1e-10)


@pytest.mark.parametrize("compiled", [False, True], ids=["numpy", "compiled"])
def test_ukf_equals_filterpy_ukf(data, compiled):
    start, zs = data
    ukf = filterpy_kalman.UnscentedKalmanFilter(
        dim_x=5,
        dim_z=3,
        dt=DT_S,
        hx=lambda x: x[:3],
        fx=CTRV.transition,
        points=filterpy_kalman.MerweScaledSigmaPoints(5, alpha=0.1, beta=2.0, kappa=0.0),
        x_mean_fn=_mean_about_centre,
        z_mean_fn=_mean_about_centre,
        residual_x=_residual,
        residual_z=_residual,
        state_add=lambda a, b: _wrap_heading(a + b),
    )
    ukf.x, ukf.P, ukf.Q, ukf.R = start.copy(), P0.copy(), Q.copy(), R.copy()
    theirs = []
    for z in zs:
        ukf.predict()
        ukf.update(z)
        theirs.append((ukf.x.copy(), ukf.P.copy()))
    ours = _ours(
        UnscentedKalmanFilter(ScaledSigmaPoints(alpha=0.1, beta=2.0, kappa=0.0)),
        start,
        zs,
        compiled,
    )
    _assert_same(ours, theirs)


def test_ekf_equals_filterpy_ekf(data):
    start, zs = data
    ekf = _NonlinearEKF(dim_x=5, dim_z=3)
    ekf.x, ekf.P, ekf.Q, ekf.R = start.copy(), P0.copy(), Q.copy(), R.copy()
    theirs = []
    for z in zs:
        ekf.F = CTRV.jacobian(ekf.x, DT_S)
        ekf.predict()
        ekf.update(z, lambda x: H, lambda x: x[:3], residual=_residual)
        theirs.append((ekf.x.copy(), ekf.P.copy()))
    _assert_same(_ours(ExtendedKalmanFilter(), start, zs), theirs)
