"""The compiled UKF path (localization.compiled.ukf) against the numpy path, its reference.

Each model is run twice through the same :class:`UnscentedKalmanFilter`: once with its
per-point kernel (compiled path) and once as the same batched function without a kernel
(numpy path). With sigma points of moderate spread (``alpha = 0.5``) the two agree to
rounding (1e-12 relative); with ``alpha = 1e-3`` the mean's second-order term is a finite
difference of step ``gamma`` and amplifies the rounding of the images by ``1 / gamma^2``
(module docstring of localization.sigma_points), so that comparison gets a tolerance derived
from it. Compile time counts: the built-in entries are cached on disk after a first run.
"""

from __future__ import annotations

import dataclasses
import math
import warnings

import numba
import numpy as np
import pytest

from localization.compiled import ukf as compiled_ukf
from localization.compiled.glue import pack_args
from localization.errors import EstimationError
from localization.gaussian import Gaussian
from localization.linalg import CovarianceRepairWarning, PDPolicy
from localization.models import MeasurementModel, ProcessModel
from localization.motion_models import MODELS, gps_model, pose_model
from localization.sigma_points import ScaledSigmaPoints
from localization.ukf import UnscentedKalmanFilter

UKF = UnscentedKalmanFilter(ScaledSigmaPoints(alpha=0.5))
DT_S = 0.1


def numpy_twin(model):
    """The same model without its kernel: the UKF then takes the numpy path."""
    return dataclasses.replace(model, point=None)


def compiled_step_runs(belief: Gaussian, model, *args) -> bool:
    """Whether the compiled path takes this step itself (no fallback to the numpy path)."""
    if isinstance(model, ProcessModel):
        dim = belief.dim + (model.Q.shape[-1] if model.noise == "augmented" else 0)
        done = compiled_ukf.predict(
            UKF.points.weights(dim), belief.mean, belief.cov, belief.angle_indices, model, args
        )
    else:
        z, *args = args
        done = compiled_ukf.update(
            UKF.points.weights(belief.dim),
            belief.mean,
            belief.cov,
            belief.angle_indices,
            z,
            model,
            tuple(args),
        )
    return done is not None


def process_models(motion, noise: str) -> ProcessModel:
    if noise == "additive":
        return motion.process_model(np.diag(np.linspace(0.01, 0.05, motion.n)))
    return motion.process_model(np.diag([0.04, 0.01]), noise="augmented")


@pytest.mark.parametrize("noise", ["additive", "augmented"])
@pytest.mark.parametrize("name", sorted(MODELS))
def test_predict_matches_numpy_path(name, noise, random_belief, assert_close):
    motion = MODELS[name]
    compiled = process_models(motion, noise)
    assert compiled.point is not None
    reference = numpy_twin(compiled)
    rng = np.random.default_rng(3)
    belief = random_belief(rng, motion.n, 24, motion.angle_indices)
    assert compiled_step_runs(belief, compiled, DT_S)
    batched = UKF.predict(belief, compiled, DT_S)
    assert_close(batched, UKF.predict(belief, reference, DT_S))
    if motion.angle_indices:
        assert np.abs(batched.mean[:, 2]).max() > 3.0, "headings near +-pi must be exercised"
    for run in (0, 1, 5):  # one run alone: the batch's numbers bit for bit
        single = UKF.predict(belief[run], compiled, DT_S)
        np.testing.assert_array_equal(single.mean, batched.mean[run])
        np.testing.assert_array_equal(single.cov, batched.cov[run])
        assert_close(single, UKF.predict(belief[run], reference, DT_S))


@pytest.mark.parametrize("measurement", ["pose", "gps"])
def test_update_matches_numpy_path(measurement, random_belief, assert_close):
    motion = MODELS["CTRV"]
    compiled = (
        pose_model(np.diag([0.3, 0.2, 0.05]))
        if measurement == "pose"
        else gps_model(np.diag([0.3, 0.2]))
    )
    reference = numpy_twin(compiled)
    rng = np.random.default_rng(5)
    belief = random_belief(rng, motion.n, 24, motion.angle_indices)
    m = compiled.R.shape[0]
    z = belief.mean[:, :m] + rng.normal(size=(24, m)) * 0.3
    if m == 3:
        z[:, 2] = -np.sign(belief.mean[:, 2]) * (math.pi - 0.01)  # the innovation wraps
    assert compiled_step_runs(belief, compiled, z)
    batched = UKF.update(belief, z, compiled)
    assert_close(batched, UKF.update(belief, z, reference))
    for run in (0, 7):
        single = UKF.update(belief[run], z[run], compiled)
        np.testing.assert_array_equal(single.mean, batched.mean[run])
        np.testing.assert_array_equal(single.cov, batched.cov[run])


def test_tiny_alpha_within_the_finite_difference_rounding(random_belief, assert_close):
    """alpha = 1e-3 (issue 3's benchmark): the mean's second-order term carries a rounding of
    about ``eps |y| / gamma^2`` in both paths, differently rounded; the rest agrees to 1e-12."""
    ukf = UnscentedKalmanFilter(ScaledSigmaPoints(alpha=1e-3))
    motion = MODELS["CTRV"]
    compiled = process_models(motion, "additive")
    belief = random_belief(np.random.default_rng(11), motion.n, 16, motion.angle_indices)
    gamma2 = ukf.points.weights(motion.n).gamma ** 2
    scale = np.abs(belief.mean).max() + 10.0
    predicted = ukf.predict(belief, compiled, DT_S)
    assert_close(
        predicted,
        ukf.predict(belief, numpy_twin(compiled), DT_S),
        atol=50 * np.finfo(float).eps * scale / gamma2,
    )


def test_per_run_arguments_and_noise(random_belief, assert_close):
    """Per-run ``dt_s (B,)`` and per-run ``Q (B, n, n)`` are packed per run."""
    motion = MODELS["CTRA"]
    rng = np.random.default_rng(2)
    belief = random_belief(rng, motion.n, 10, motion.angle_indices)
    q_cov = np.einsum("b,ij->bij", rng.uniform(0.5, 2.0, 10), 0.01 * np.eye(motion.n))
    compiled = motion.process_model(q_cov)
    dt = rng.uniform(0.05, 0.2, 10)
    assert compiled_step_runs(belief, compiled, dt)
    predicted = UKF.predict(belief, compiled, dt)
    assert_close(predicted, UKF.predict(belief, numpy_twin(compiled), dt))
    np.testing.assert_array_equal(
        predicted.mean[4],
        UKF.predict(belief[4:5], motion.process_model(q_cov[4:5]), dt[4:5]).mean[0],
    )


def test_non_positive_definite_falls_back_to_the_policy(random_belief):
    """A non-PD covariance: the compiled step declines and the numpy step applies the policy,
    with the same error, the same warning and the same repaired result."""
    motion = MODELS["CTRV"]
    compiled = process_models(motion, "additive")
    belief = random_belief(np.random.default_rng(4), motion.n, 6, motion.angle_indices)
    cov = np.array(belief.cov)
    cov[2] = np.diag([1.0, 1.0, -1e-3, 1.0, 1.0])
    broken = Gaussian(belief.mean, cov, belief.angle_indices)
    assert not compiled_step_runs(broken, compiled, DT_S)
    messages = []
    for model in (compiled, numpy_twin(compiled)):
        with pytest.raises(EstimationError, match="not positive definite") as raised:
            UKF.predict(broken, model, DT_S)
        messages.append(str(raised.value))
    assert messages[0] == messages[1]
    repairing = UnscentedKalmanFilter(UKF.points, PDPolicy("repair"))
    results = []
    for model in (compiled, numpy_twin(compiled)):
        with pytest.warns(CovarianceRepairWarning, match="jitter") as caught:
            results.append(repairing.predict(broken, model, DT_S))
        messages.append(str(caught[0].message))
    assert messages[2] == messages[3]
    np.testing.assert_array_equal(results[0].mean, results[1].mean)
    np.testing.assert_array_equal(results[0].cov, results[1].cov)
    measurement = pose_model(np.eye(3))
    z = np.zeros((6, 3))
    with pytest.raises(
        EstimationError, match="UKF update: the covariance is not positive definite"
    ):
        UKF.update(broken, z, measurement)


def test_non_finite_inputs_refused_as_by_the_numpy_path(random_belief):
    motion = MODELS["CTRV"]
    compiled = process_models(motion, "additive")
    belief = random_belief(np.random.default_rng(8), motion.n, 3, motion.angle_indices)
    for model in (compiled, numpy_twin(compiled)):
        with pytest.raises(EstimationError, match="UKF predict: argument 1 is not finite"):
            UKF.predict(belief, model, math.nan)
    z = np.zeros((3, 3))
    z[1, 0] = math.inf
    for model in (pose_model(np.eye(3)), numpy_twin(pose_model(np.eye(3)))):
        with pytest.raises(EstimationError, match="UKF update: the measurement z is not finite"):
            UKF.update(belief, z, model)
        with pytest.raises(EstimationError, match="has shape"):
            UKF.update(belief, np.zeros((3, 2)), model)


@numba.njit
def damped_point(x, args, out):
    """A user's kernel: ``x' = x * exp(-k dt) + sin(x) dt`` with ``args = (k, dt_s)``."""
    for i in range(x.shape[0]):
        out[i] = x[i] * math.exp(-args[0] * args[1]) + math.sin(x[i]) * args[1]


def damped(x, k, dt_s):
    """The same model, batched (numpy path; a per-run ``k`` arrives as ``(B, 1)``)."""
    return x * np.exp(-np.asarray(k)[..., None] * dt_s) + np.sin(x) * dt_s


@pytest.mark.slow
def test_user_kernel_is_compiled_once_and_matches(assert_close):
    compiled = ProcessModel(damped, 0.01 * np.eye(3), point=damped_point)
    belief = Gaussian(
        np.array([[0.5, -1.0, 2.0], [0.1, 0.2, 0.3]]), np.broadcast_to(0.2 * np.eye(3), (2, 3, 3))
    )
    rates = np.array([0.5, 2.0])  # per run
    assert compiled_step_runs(belief, compiled, rates, DT_S)
    predicted = UKF.predict(belief, compiled, rates, DT_S)
    assert_close(predicted, UKF.predict(belief, numpy_twin(compiled), rates, DT_S))
    assert compiled_ukf.predict_entry(damped_point, False) is compiled_ukf.predict_entry(
        damped_point, False
    )


def test_kernel_that_does_not_fit_gives_one_clear_error():
    @numba.njit
    def two_arguments(x, out):
        out[:] = x

    model = ProcessModel(lambda x, dt_s: x, np.eye(2), point=two_arguments)
    with pytest.raises(
        EstimationError, match="UKF predict: the kernel two_arguments does not compile"
    ):
        UKF.predict(Gaussian(np.zeros(2), np.eye(2)), model, DT_S)
    with pytest.raises(EstimationError, match=r"point must be a numba\.njit-compiled function"):
        MeasurementModel(lambda x: x, np.eye(2), point=lambda x, args, out: None)


def test_steps_the_compiled_path_cannot_take_use_the_numpy_path(random_belief):
    """Arguments that are not numbers and batches of two axes go to the numpy path unchanged."""
    motion = MODELS["CV"]
    compiled = process_models(motion, "additive")
    belief = random_belief(np.random.default_rng(9), motion.n, 4, ())
    grid = Gaussian(belief.mean.reshape(2, 2, 4), belief.cov.reshape(2, 2, 4, 4))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        two_axes = UKF.predict(grid, compiled, DT_S)
    np.testing.assert_array_equal(two_axes.mean, UKF.predict(grid, numpy_twin(compiled), DT_S).mean)
    assert pack_args(("dt",), ()) is None
    assert (
        compiled_ukf.predict(UKF.points.weights(4), grid.mean, grid.cov, (), compiled, (DT_S,))
        is None
    )
