"""A batch of runs in one call gives each run's own numbers; headings near +-pi stay right."""

from __future__ import annotations

import numpy as np
import pytest

from localization.ekf import ExtendedKalmanFilter, IteratedExtendedKalmanFilter, IterationSettings
from localization.gaussian import Gaussian
from localization.iukf import IteratedUnscentedKalmanFilter
from localization.models import MeasurementModel, ProcessModel
from localization.mukf import LinearSubsystem, ModifiedKalmanFilter
from localization.sigma_points import KappaSigmaPoints, SpreadSigmaPoints
from localization.ukf import UnscentedKalmanFilter

B = 5


def unicycle(x, u, dt):
    """State (x_m, y_m, theta_rad), control u = (v_m_s, omega_rad_s) (..., 2), dt_s (...,)."""
    dt = np.asarray(dt)[..., None] if np.ndim(dt) else dt
    v, w = u[..., 0:1], u[..., 1:2]
    theta = x[..., 2:3]
    return np.concatenate(
        [
            x[..., 0:1] + v * dt * np.cos(theta),
            x[..., 1:2] + v * dt * np.sin(theta),
            theta + w * dt,
        ],
        axis=-1,
    )


def unicycle_jacobian(x, u, dt):
    dt = np.asarray(dt) if np.ndim(dt) else dt
    jac = np.zeros(x.shape[:-1] + (3, 3))
    jac[..., 0, 0] = jac[..., 1, 1] = jac[..., 2, 2] = 1.0
    jac[..., 0, 2] = -u[..., 0] * dt * np.sin(x[..., 2])
    jac[..., 1, 2] = u[..., 0] * dt * np.cos(x[..., 2])
    return jac


def unicycle_with_noise(x, w, u, dt):
    return unicycle(x, u + w, dt)


def range_bearing(x):
    """Range (m) and bearing (rad, an angle) of the landmark (2, 1) from the robot."""
    dx, dy = 2.0 - x[..., 0], 1.0 - x[..., 1]
    return np.stack([np.hypot(dx, dy), np.arctan2(dy, dx) - x[..., 2]], axis=-1)


def range_bearing_jacobian(x):
    dx, dy = 2.0 - x[..., 0], 1.0 - x[..., 1]
    r2 = dx * dx + dy * dy
    r = np.sqrt(r2)
    jac = np.zeros(x.shape[:-1] + (2, 3))
    jac[..., 0, 0], jac[..., 0, 1] = -dx / r, -dy / r
    jac[..., 1, 0], jac[..., 1, 1], jac[..., 1, 2] = dy / r2, -dx / r2, -1.0
    return jac


PROCESS = ProcessModel(unicycle, np.diag([1e-3, 1e-3, 1e-3]), jacobian=unicycle_jacobian)
AUGMENTED = ProcessModel(unicycle_with_noise, np.diag([0.05, 0.02]), noise="augmented")
MEASUREMENT = MeasurementModel(
    range_bearing, np.diag([0.01, 0.003]), jacobian=range_bearing_jacobian, angle_indices=(1,)
)

FILTERS = {
    "UKF": (UnscentedKalmanFilter(), PROCESS),
    "UKF augmented": (UnscentedKalmanFilter(), AUGMENTED),
    "EKF": (ExtendedKalmanFilter(), PROCESS),
    "IEKF": (
        IteratedExtendedKalmanFilter(IterationSettings(max_iterations=8, tolerance=1e-6)),
        PROCESS,
    ),
    "IUKF": (
        IteratedUnscentedKalmanFilter(
            iteration=IterationSettings(max_iterations=8, tolerance=1e-6)
        ),
        PROCESS,
    ),
}


def inputs(seed):
    rng = np.random.default_rng(seed)
    mean = np.column_stack(
        [rng.normal(0, 1, B), rng.normal(0, 1, B), rng.uniform(-np.pi, np.pi, B)]
    )
    mean[0, 2] = np.pi - 1e-3
    mean[1, 2] = -np.pi + 1e-3
    roots = rng.normal(0, 0.3, (B, 3, 3))
    cov = roots @ roots.transpose(0, 2, 1) + 0.05 * np.eye(3)
    controls = np.column_stack([rng.uniform(0.5, 2, B), rng.uniform(-1, 1, B)])
    dts = rng.uniform(0.05, 0.2, B)
    z = range_bearing(mean) + rng.normal(0.0, 1.0, (B, 2)) * [0.1, 0.05]
    return mean, cov, controls, dts, z


# Near the landmark some Gauss-Newton iterations oscillate and hit the cap: the batch must
# reproduce those runs too, so the warning is expected here.
@pytest.mark.filterwarnings("ignore::localization.linalg.ConvergenceWarning")
@pytest.mark.parametrize("name", list(FILTERS))
def test_batched_equals_looped(name):
    kf, process = FILTERS[name]
    mean, cov, controls, dts, z = inputs(1)
    batch = Gaussian(mean, cov, angle_indices=(2,))
    for _ in range(3):
        batch = kf.update(kf.predict(batch, process, controls, dts), z, MEASUREMENT)
    for i in range(B):
        single = Gaussian(mean[i], cov[i], angle_indices=(2,))
        for _ in range(3):
            single = kf.update(kf.predict(single, process, controls[i], dts[i]), z[i], MEASUREMENT)
        np.testing.assert_allclose(batch.mean[i], single.mean, rtol=1e-12, atol=1e-12, err_msg=name)
        np.testing.assert_allclose(batch.cov[i], single.cov, rtol=1e-12, atol=1e-12, err_msg=name)
    assert (batch.mean[:, 2] >= -np.pi).all() and (batch.mean[:, 2] < np.pi).all()


def test_modified_filters_batched_equal_looped():
    subsystem = LinearSubsystem(
        2,
        transition=lambda y: np.stack(
            [
                np.stack([1 - 0.1 * y[..., 0], np.full_like(y[..., 0], 0.1)], -1),
                np.stack([np.full_like(y[..., 0], -0.1), np.ones_like(y[..., 0])], -1),
            ],
            -2,
        ),
        observation=lambda x, y: np.broadcast_to(np.array([[1.0, 0.0]]), x.shape[:-1] + (1, 2)),
    )

    def f(s):
        return np.stack(
            [
                (1 - 0.1 * s[..., 2]) * s[..., 0] + 0.1 * s[..., 1],
                -0.1 * s[..., 0] + s[..., 1],
                s[..., 2],
            ],
            -1,
        )

    def f_jac(s):
        jac = np.zeros(s.shape[:-1] + (3, 3))
        jac[..., 0, 0], jac[..., 0, 1], jac[..., 0, 2] = 1 - 0.1 * s[..., 2], 0.1, -0.1 * s[..., 0]
        jac[..., 1, 0], jac[..., 1, 1], jac[..., 2, 2] = -0.1, 1.0, 1.0
        return jac

    process = ProcessModel(f, 1e-4 * np.eye(3), jacobian=f_jac)
    measurement = MeasurementModel(
        lambda s: s[..., :1],
        np.array([[1e-3]]),
        jacobian=lambda s: np.broadcast_to(np.array([[1.0, 0, 0]]), s.shape[:-1] + (1, 3)),
    )
    rng = np.random.default_rng(4)
    mean = rng.normal(1.0, 0.2, (B, 3))
    zs = rng.normal(1.0, 0.2, (4, B, 1))
    for inner in (UnscentedKalmanFilter(SpreadSigmaPoints(a=0.5)), ExtendedKalmanFilter()):
        mkf = ModifiedKalmanFilter(inner, subsystem)
        batch = mkf.initial(Gaussian(mean, np.broadcast_to(0.01 * np.eye(3), (B, 3, 3))))
        for z in zs:
            batch = mkf.update(mkf.predict(batch, process), z, measurement)
        for i in range(B):
            single = mkf.initial(Gaussian(mean[i], 0.01 * np.eye(3)))
            for z in zs:
                single = mkf.update(mkf.predict(single, process), z[i], measurement)
            np.testing.assert_allclose(batch.estimate[i], single.estimate, rtol=1e-12, atol=1e-13)
            np.testing.assert_allclose(batch.full.cov[i], single.full.cov, rtol=1e-12, atol=1e-13)


def heading_filter():
    """State (theta_rad, omega_rad_s); theta measured directly."""
    process = ProcessModel(
        lambda x, dt: np.stack([x[..., 0] + dt * x[..., 1], x[..., 1]], axis=-1),
        np.diag([1e-4, 1e-3]),
        jacobian=lambda x, dt: np.broadcast_to(
            np.array([[1.0, dt], [0.0, 1.0]]), x.shape[:-1] + (2, 2)
        ),
    )
    measurement = MeasurementModel(
        lambda x: x[..., :1],
        np.array([[0.01]]),
        jacobian=lambda x: np.broadcast_to(np.array([[1.0, 0.0]]), x.shape[:-1] + (1, 2)),
        angle_indices=(0,),
    )
    return process, measurement


@pytest.mark.parametrize(
    "kf",
    [
        UnscentedKalmanFilter(),
        UnscentedKalmanFilter(KappaSigmaPoints()),
        ExtendedKalmanFilter(),
        IteratedExtendedKalmanFilter(),
        IteratedUnscentedKalmanFilter(),
    ],
    ids=["UKF", "UKF-kappa", "EKF", "IEKF", "IUKF"],
)
def test_heading_across_pi_equals_the_same_problem_away_from_it(kf):
    """Turning through +-pi gives the estimates of the same problem rotated to 0, wrapped."""
    process, measurement = heading_filter()
    rng = np.random.default_rng(2)
    truth = np.pi - 0.3 + 0.2 * np.arange(1, 9)  # crosses pi at step 2
    noise = rng.normal(0.0, 0.1, truth.size)
    shifted = Gaussian(np.array([np.pi - 0.3, 0.2]), np.diag([0.5, 0.1]), angle_indices=(0,))
    centred = Gaussian(np.array([-0.3, 0.2]), np.diag([0.5, 0.1]), angle_indices=(0,))
    for k in range(truth.size):
        shifted = kf.update(
            kf.predict(shifted, process, 1.0), np.array([truth[k] + noise[k]]), measurement
        )
        centred = kf.update(
            kf.predict(centred, process, 1.0), np.array([truth[k] - np.pi + noise[k]]), measurement
        )
        diff = (shifted.mean[0] - centred.mean[0] - np.pi + np.pi) % (2 * np.pi) - np.pi
        assert abs(diff) < 1e-9
        assert -np.pi <= shifted.mean[0] < np.pi
        np.testing.assert_allclose(shifted.cov, centred.cov, atol=1e-12)
    assert abs(shifted.mean[1] - 0.2) < 0.1  # the turn rate was not corrupted by the wrap
