"""Numerical safeguards: PD policy, refusal of non-finite inputs, iteration cap, validation."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from localization.ekf import ExtendedKalmanFilter, IteratedExtendedKalmanFilter, IterationSettings
from localization.errors import EstimationError
from localization.gaussian import Gaussian
from localization.iukf import IteratedUnscentedKalmanFilter
from localization.linalg import ConvergenceWarning, CovarianceRepairWarning, PDPolicy
from localization.models import MeasurementModel, ProcessModel
from localization.ukf import UnscentedKalmanFilter

INDEFINITE = np.array([[1.0, 2.0], [2.0, 1.0]])  # eigenvalues 3 and -1


def identity_process():
    return ProcessModel(
        lambda x: x + 0.0,
        0.01 * np.eye(2),
        jacobian=lambda x: np.broadcast_to(np.eye(2), x.shape + (2,)),
    )


def product_measurement():
    return MeasurementModel(
        lambda x: (x[..., 0] * x[..., 1])[..., None],
        np.array([[0.1]]),
        jacobian=lambda x: np.stack([x[..., 1], x[..., 0]], axis=-1)[..., None, :],
    )


def test_raise_policy_names_the_step():
    ukf = UnscentedKalmanFilter()
    belief = Gaussian(np.zeros(2), INDEFINITE)
    with pytest.raises(
        EstimationError, match="UKF predict: the covariance is not positive definite"
    ):
        ukf.predict(belief, identity_process())
    with pytest.raises(EstimationError, match="UKF update"):
        ukf.update(belief, np.array([0.0]), product_measurement())


def test_repair_policy_reports_the_jitter_and_only_touches_the_broken_run():
    ukf = UnscentedKalmanFilter(pd_policy=PDPolicy(action="repair"))
    good = np.array([[2.0, 0.5], [0.5, 1.0]])
    batch = Gaussian(np.zeros((2, 2)), np.stack([good, INDEFINITE]))
    with pytest.warns(CovarianceRepairWarning, match=r"jitter of 1(\.0+)?\d*"):
        out = ukf.predict(batch, identity_process())
    assert np.isfinite(out.cov).all()
    assert np.linalg.eigvalsh(out.cov[1]).min() > 0.0
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        alone = ukf.predict(Gaussian(np.zeros(2), good), identity_process())
    np.testing.assert_allclose(out.cov[0], alone.cov, atol=1e-14)
    with pytest.warns(CovarianceRepairWarning):
        updated = ukf.update(
            Gaussian(np.ones(2), INDEFINITE), np.array([1.0]), product_measurement()
        )
    assert np.linalg.eigvalsh(updated.cov).min() > 0.0  # the update went on from the repaired prior


@pytest.mark.parametrize(
    "kf",
    [
        UnscentedKalmanFilter(),
        ExtendedKalmanFilter(),
        IteratedExtendedKalmanFilter(),
        IteratedUnscentedKalmanFilter(),
    ],
)
def test_non_finite_inputs_are_refused(kf):
    belief = Gaussian(np.array([1.0, 2.0]), np.eye(2))
    with pytest.raises(EstimationError, match="update: the measurement z is not finite"):
        kf.update(belief, np.array([np.nan]), product_measurement())
    with pytest.raises(EstimationError, match="argument 1 is not finite"):
        kf.predict(
            belief,
            ProcessModel(lambda x, dt: x * dt, np.eye(2), jacobian=lambda x, dt: np.eye(2) * dt),
            float("inf"),
        )
    nan_model = ProcessModel(
        lambda x: x * np.nan,
        np.eye(2),
        jacobian=lambda x: np.broadcast_to(np.eye(2), x.shape + (2,)),
    )
    with pytest.raises(EstimationError, match="predict: the predicted mean"):
        kf.predict(belief, nan_model)


def test_beliefs_and_models_are_validated_at_construction():
    with pytest.raises(EstimationError, match="not finite"):
        Gaussian(np.array([0.0, np.inf]), np.eye(2))
    with pytest.raises(EstimationError, match="cov shape"):
        Gaussian(np.zeros(3), np.eye(2))
    with pytest.raises(EstimationError, match="angle_indices"):
        Gaussian(np.zeros(2), np.eye(2), angle_indices=(2,))
    with pytest.raises(EstimationError, match="positive semi-definite"):
        ProcessModel(lambda x: x, INDEFINITE)
    with pytest.raises(EstimationError, match="noise must be"):
        ProcessModel(lambda x: x, np.eye(2), noise="multiplicative")
    with pytest.raises(EstimationError, match="R is not finite"):
        MeasurementModel(lambda x: x, np.array([[np.nan]]))
    with pytest.raises(EstimationError, match="action"):
        PDPolicy(action="ignore")
    with pytest.raises(EstimationError, match="max_iterations"):
        IterationSettings(max_iterations=0)
    with pytest.raises(EstimationError, match="jacobian"):
        ExtendedKalmanFilter().predict(
            Gaussian(np.zeros(2), np.eye(2)), ProcessModel(lambda x: x, np.eye(2))
        )


def test_a_belief_is_immutable_and_wrapped():
    belief = Gaussian(np.array([0.0, 3 * np.pi / 2]), np.diag([4.0, 0.25]), angle_indices=(1,))
    assert belief.mean[1] == pytest.approx(-np.pi / 2)
    np.testing.assert_allclose(belief.std, [2.0, 0.5])
    np.testing.assert_allclose(
        belief.residual(np.array([1.0, np.pi / 2 + 0.1])), [1.0, -np.pi + 0.1]
    )
    batch = Gaussian(np.zeros((4, 2)), np.broadcast_to(np.eye(2), (4, 2, 2)))
    assert (
        batch.batch_shape == (4,) and batch[1:3].mean.shape == (2, 2) and batch[0].batch_shape == ()
    )
    with pytest.raises(EstimationError, match="cannot be indexed"):
        belief[0]
    with pytest.raises(ValueError):
        belief.mean[0] = 1.0
    with pytest.raises(AttributeError):
        belief.mean = np.zeros(2)
    predicted = UnscentedKalmanFilter().predict(belief, identity_process())
    with pytest.raises(ValueError):
        predicted.cov[0, 0] = 1.0


@pytest.mark.parametrize("kf_class", [IteratedExtendedKalmanFilter, IteratedUnscentedKalmanFilter])
def test_iteration_cap_warns_and_a_fixed_count_does_not(kf_class):
    belief = Gaussian(np.array([1.0, 2.0]), np.eye(2))
    z = np.array([7.0])
    capped = kf_class(iteration=IterationSettings(max_iterations=1, tolerance=1e-12))
    with pytest.warns(ConvergenceWarning, match="1 run\\(s\\) did not converge"):
        capped.update(belief, z, product_measurement())
    fixed = kf_class(iteration=IterationSettings(max_iterations=3, tolerance=None))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        fixed.update(belief, z, product_measurement())
    converging = kf_class(iteration=IterationSettings(max_iterations=50, tolerance=1e-10))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out = converging.update(belief, z, product_measurement())
    # at convergence the iterate is the MAP of eq. 7: its gradient vanishes
    x = out.mean
    residual = z[0] - x[0] * x[1]
    grad = np.linalg.solve(np.eye(2), x - belief.mean) - np.array([x[1], x[0]]) * residual / 0.1
    np.testing.assert_allclose(grad, 0.0, atol=1e-7)


@pytest.mark.parametrize(
    "kf", [UnscentedKalmanFilter(), ExtendedKalmanFilter(), IteratedUnscentedKalmanFilter()]
)
def test_a_measurement_of_the_wrong_shape_is_refused_not_broadcast(kf):
    batch = Gaussian(np.ones((3, 2)), np.broadcast_to(np.eye(2), (3, 2, 2)))
    with pytest.raises(EstimationError, match=r"z has shape \(1,\), expected \(3, 1\)"):
        kf.update(batch, np.array([0.5]), product_measurement())


def test_augmented_noise_accepts_a_singular_covariance():
    """Noise on one input only: Q = diag(q, 0) has no Cholesky factor, its square root is used."""
    model = ProcessModel(lambda x, w: x + w, np.diag([0.3, 0.0]), noise="augmented")
    out = UnscentedKalmanFilter().predict(Gaussian(np.zeros(2), np.eye(2)), model)
    np.testing.assert_allclose(out.cov, np.diag([1.3, 1.0]), atol=1e-12)
