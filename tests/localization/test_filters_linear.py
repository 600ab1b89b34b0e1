"""On a linear-Gaussian model every filter of the family must be the Kalman filter.

The reference is a textbook Kalman filter written here independently (explicit inverse,
standard covariance update), on random linear systems drawn by hypothesis.
"""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from localization.ekf import ExtendedKalmanFilter, IteratedExtendedKalmanFilter, IterationSettings
from localization.gaussian import Gaussian
from localization.iukf import IteratedUnscentedKalmanFilter
from localization.models import MeasurementModel, ProcessModel
from localization.mukf import LinearSubsystem, ModifiedKalmanFilter
from localization.sigma_points import KappaSigmaPoints, ScaledSigmaPoints, SpreadSigmaPoints
from localization.ukf import UnscentedKalmanFilter


def textbook_kalman(x0, p0, a, q, h, r, measurements):
    """Means and covariances of the linear Kalman filter after each predict + update."""
    x, p = x0.copy(), p0.copy()
    out = []
    for z in measurements:
        x = a @ x
        p = a @ p @ a.T + q
        s = h @ p @ h.T + r
        k = p @ h.T @ np.linalg.inv(s)
        x = x + k @ (z - h @ x)
        p = (np.eye(len(x)) - k @ h) @ p
        out.append((x, p))
    return out


def random_spd(rng, n, low=0.1, high=2.0):
    basis, _ = np.linalg.qr(rng.standard_normal((n, n)))
    return basis @ np.diag(rng.uniform(low, high, n)) @ basis.T


def linear_problem(seed: int, n: int, m: int, steps: int = 8):
    rng = np.random.default_rng(seed)
    a = np.eye(n) + 0.2 * rng.standard_normal((n, n))
    h = rng.standard_normal((m, n))
    q, r, p0 = random_spd(rng, n, 0.01, 0.5), random_spd(rng, m, 0.05, 1.0), random_spd(rng, n)
    x0 = rng.standard_normal(n)
    zs = rng.standard_normal((steps, m)) * 3.0
    process = ProcessModel(
        lambda x: x @ a.T, q, jacobian=lambda x: np.broadcast_to(a, x.shape[:-1] + (n, n))
    )
    measurement = MeasurementModel(
        lambda x: x @ h.T, r, jacobian=lambda x: np.broadcast_to(h, x.shape[:-1] + (m, n))
    )
    return x0, p0, a, q, h, r, zs, process, measurement


FILTERS = {
    "UKF scaled": UnscentedKalmanFilter(ScaledSigmaPoints(alpha=0.5, beta=2.0, kappa=0.0)),
    "UKF kappa": UnscentedKalmanFilter(KappaSigmaPoints(kappa=1.0)),
    "UKF spread": UnscentedKalmanFilter(SpreadSigmaPoints(a=0.7)),
    "EKF": ExtendedKalmanFilter(),
    "IEKF": IteratedExtendedKalmanFilter(IterationSettings(max_iterations=5, tolerance=1e-10)),
    "IUKF": IteratedUnscentedKalmanFilter(
        iteration=IterationSettings(max_iterations=5, tolerance=1e-10)
    ),
}


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 4), m=st.integers(1, 3))
def test_every_filter_equals_the_linear_kalman_filter(seed, n, m):
    x0, p0, a, q, h, r, zs, process, measurement = linear_problem(seed, n, m)
    reference = textbook_kalman(x0, p0, a, q, h, r, zs)
    for name, kf in FILTERS.items():
        belief = Gaussian(x0, p0)
        for (x_ref, p_ref), z in zip(reference, zs, strict=True):
            belief = kf.update(kf.predict(belief, process), z, measurement)
            scale = 1.0 + np.abs(x_ref).max()
            np.testing.assert_allclose(belief.mean, x_ref, rtol=0, atol=1e-9 * scale, err_msg=name)
            np.testing.assert_allclose(
                belief.cov, p_ref, rtol=0, atol=1e-9 * (1 + np.abs(p_ref).max()), err_msg=name
            )


def test_tiny_alpha_still_equals_the_kalman_filter():
    """Paper 001's alpha = 1e-5 (Wm_0 ~ -1e10): the centre-point moments stay accurate."""
    x0, p0, a, q, h, r, zs, process, measurement = linear_problem(7, 5, 3)
    reference = textbook_kalman(x0, p0, a, q, h, r, zs)
    kf = UnscentedKalmanFilter(ScaledSigmaPoints(alpha=1e-5, beta=2.0, kappa=None))
    belief = Gaussian(x0, p0)
    for (x_ref, p_ref), z in zip(reference, zs, strict=True):
        belief = kf.update(kf.predict(belief, process), z, measurement)
        # rounding of the deviations is amplified by 1/gamma^2 ~ 3e9 in the mean only
        np.testing.assert_allclose(belief.mean, x_ref, atol=1e-5)
        np.testing.assert_allclose(belief.cov, p_ref, atol=1e-8)


def test_augmented_noise_equals_additive_noise_on_a_linear_model():
    x0, p0, a, q, _, _, zs, process, measurement = linear_problem(3, 3, 2)
    augmented = ProcessModel(lambda x, w: x @ a.T + w, q, noise="augmented")
    kf = UnscentedKalmanFilter(ScaledSigmaPoints(alpha=0.3))
    additive_belief = augmented_belief = Gaussian(x0, p0)
    for z in zs:
        additive_belief = kf.update(kf.predict(additive_belief, process), z, measurement)
        augmented_belief = kf.update(kf.predict(augmented_belief, augmented), z, measurement)
    np.testing.assert_allclose(augmented_belief.mean, additive_belief.mean, atol=1e-10)
    np.testing.assert_allclose(augmented_belief.cov, additive_belief.cov, atol=1e-10)


@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_iekf_with_one_iteration_is_the_ekf_on_a_nonlinear_model(seed):
    rng = np.random.default_rng(seed)
    process = ProcessModel(
        lambda x: np.stack([x[..., 0] + 0.1 * np.sin(x[..., 1]), 0.9 * x[..., 1]], axis=-1),
        np.diag([0.01, 0.02]),
        jacobian=lambda x: np.stack(
            [
                np.stack([np.ones_like(x[..., 0]), 0.1 * np.cos(x[..., 1])], axis=-1),
                np.stack([np.zeros_like(x[..., 0]), np.full_like(x[..., 0], 0.9)], axis=-1),
            ],
            axis=-2,
        ),
    )
    measurement = MeasurementModel(
        lambda x: (x[..., 0] * x[..., 1] ** 2)[..., None],
        np.array([[0.5]]),
        jacobian=lambda x: np.stack([x[..., 1] ** 2, 2 * x[..., 0] * x[..., 1]], axis=-1)[
            ..., None, :
        ],
    )
    ekf = ExtendedKalmanFilter()
    iekf = IteratedExtendedKalmanFilter(IterationSettings(max_iterations=1, tolerance=None))
    b_ekf = b_iekf = Gaussian(rng.standard_normal(2) + 1.0, np.diag(rng.uniform(0.1, 1.0, 2)))
    for z in rng.standard_normal((6, 1)):
        b_ekf = ekf.update(ekf.predict(b_ekf, process), z, measurement)
        b_iekf = iekf.update(iekf.predict(b_iekf, process), z, measurement)
        np.testing.assert_allclose(b_iekf.mean, b_ekf.mean, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(b_iekf.cov, b_ekf.cov, rtol=1e-12, atol=1e-12)


def test_modified_filters_reduce_to_kalman_filters_on_a_decoupled_linear_model():
    """With y not entering F or H, Algorithm II is the KF of x and Algorithm I the KF of (x, y)."""
    rng = np.random.default_rng(11)
    a_x = np.array([[0.9, 0.1], [-0.1, 1.0]])
    a = np.eye(3)
    a[:2, :2] = a_x
    h = np.array([[1.0, 0.0, 0.0]])
    q, r = np.diag([1e-3, 2e-3, 1e-4]), np.array([[1e-2]])
    p0 = np.diag([0.5, 0.4, 0.3])
    x0 = np.array([1.0, -0.5, 0.2])
    zs = rng.standard_normal((10, 1))
    process = ProcessModel(
        lambda s: s @ a.T, q, jacobian=lambda s: np.broadcast_to(a, s.shape[:-1] + (3, 3))
    )
    measurement = MeasurementModel(
        lambda s: s @ h.T, r, jacobian=lambda s: np.broadcast_to(h, s.shape[:-1] + (1, 3))
    )
    subsystem = LinearSubsystem(
        2,
        transition=lambda y: np.broadcast_to(a_x, y.shape[:-1] + (2, 2)),
        observation=lambda x, y: np.broadcast_to(h[:, :2], x.shape[:-1] + (1, 2)),
    )
    full_ref = textbook_kalman(x0, p0, a, q, h, r, zs)
    linear_ref = textbook_kalman(x0[:2], p0[:2, :2], a_x, q[:2, :2], h[:, :2], r, zs)
    for inner in (UnscentedKalmanFilter(SpreadSigmaPoints(a=0.8)), ExtendedKalmanFilter()):
        mkf = ModifiedKalmanFilter(inner, subsystem)
        belief = mkf.initial(Gaussian(x0, p0))
        for z, (x_full, p_full), (x_lin, p_lin) in zip(zs, full_ref, linear_ref, strict=True):
            belief = mkf.update(mkf.predict(belief, process), z, measurement)
            np.testing.assert_allclose(belief.full.mean, x_full, atol=1e-10, err_msg=mkf.name)
            np.testing.assert_allclose(belief.full.cov, p_full, atol=1e-10, err_msg=mkf.name)
            np.testing.assert_allclose(belief.linear.mean, x_lin, atol=1e-10, err_msg=mkf.name)
            np.testing.assert_allclose(belief.linear.cov, p_lin, atol=1e-10, err_msg=mkf.name)
            np.testing.assert_allclose(
                belief.estimate, np.concatenate([x_lin, x_full[2:]]), atol=1e-10
            )
