"""The compiled EKF path (localization.compiled.ekf) against the numpy EKF, its reference.

Each model is run twice through the same :class:`ExtendedKalmanFilter`: once with its
per-point kernels (compiled path) and once as the same batched functions without the Jacobian
kernel (numpy path). They agree to rounding (1e-12 relative); a batch gives its runs'
one-by-one results bit for bit. The Jacobian kernels are compared with the numpy Jacobians
(which ``test_motion_models.py`` checks against finite differences), on both branches of the
trigonometric moments (turned angles below and above the series threshold, and exactly 0).
"""

from __future__ import annotations

import dataclasses
import math

import numba
import numpy as np
import pytest

from localization.compiled import ekf as compiled_ekf
from localization.compiled.motion import leading_entries_jacobian_point
from localization.ekf import ExtendedKalmanFilter, IteratedExtendedKalmanFilter
from localization.errors import EstimationError
from localization.gaussian import Gaussian
from localization.models import MeasurementModel, ProcessModel
from localization.motion_models import (
    MODELS,
    gps_jacobian,
    gps_model,
    pose_jacobian,
    pose_model,
)

EKF = ExtendedKalmanFilter()
DT_S = 0.1


def numpy_twin(model):
    """The same model without its Jacobian kernel: the EKF then takes the numpy path."""
    return dataclasses.replace(model, jacobian_point=None)


def additive_model(motion) -> ProcessModel:
    return motion.process_model(np.diag(np.linspace(0.01, 0.05, motion.n)))


def takes_compiled_path(belief: Gaussian, model, *args) -> bool:
    """Whether the compiled path takes this step itself (no fallback to the numpy path)."""
    if isinstance(model, ProcessModel):
        done = compiled_ekf.predict(belief.mean, belief.cov, belief.angle_indices, model, args)
    else:
        z, *args = args
        done = compiled_ekf.update(
            belief.mean, belief.cov, belief.angle_indices, z, model, tuple(args)
        )
    return done is not None


def assert_bitwise_runs(batched: Gaussian, one_by_one, runs) -> None:
    for run in runs:
        single = one_by_one(run)
        np.testing.assert_array_equal(single.mean, batched.mean[run])
        np.testing.assert_array_equal(single.cov, batched.cov[run])


@pytest.mark.parametrize("name", sorted(MODELS))
def test_jacobian_kernels_match_finite_differences_of_the_transition_kernels(name):
    """The Jacobian kernels as the compiled EKF calls them (one state, ``args (1,)``) against
    central differences of the transition kernels, at the turned angles where the moments
    switch branches (0, tiny, around the series threshold, large) and across the heading wrap."""
    motion = MODELS[name]
    rng = np.random.default_rng(21)
    states = rng.normal(size=(40, motion.n)) * 2.0
    turn = -1  # omega (CTRV, CTRA), c (CCA) or vy (CV): turned angles 0, tiny, near the series threshold, large
    states[:4, turn] = [0.0, 1e-12, -1e-9, 0.0]
    states[4:8, turn] = np.array([0.099, 0.1, -0.101, 0.5]) / DT_S
    if motion.angle_indices:
        states[8:12, 2] = [math.pi - 1e-9, -math.pi, 3.1, -3.1]
    out, plus, minus = np.empty((motion.n, motion.n)), np.empty(motion.n), np.empty(motion.n)
    args = np.array([DT_S])
    for state in states:
        out[:] = np.nan
        motion.jacobian_point(state, args, out)
        for j in range(motion.n):
            h = 1e-6 * max(1.0, abs(state[j]))
            bumped = state.copy()
            bumped[j] += h
            motion.point(bumped, args, plus)
            bumped[j] -= 2 * h
            motion.point(bumped, args, minus)
            column = plus - minus
            for i in motion.angle_indices:  # the wrapped heading may jump by 2 pi
                column[i] = (column[i] + math.pi) % (2 * math.pi) - math.pi
            np.testing.assert_allclose(out[:, j], column / (2 * h), rtol=1e-6, atol=1e-7)
    if name == "CTRV":  # the straight line: F[0:2, 4] is the second-order term of the arc
        motion.jacobian_point(np.array([0.0, 0.0, 0.0, 2.0, 0.0]), args, out)
        np.testing.assert_allclose(out[:2, 4], [0.0, 0.5 * 2.0 * DT_S**2], rtol=1e-15)


def test_leading_entries_jacobian_kernel():
    x = np.arange(5.0)
    for m, numpy_jacobian in ((2, gps_jacobian), (3, pose_jacobian)):
        out = np.full((m, 5), np.nan)
        leading_entries_jacobian_point(x, np.empty(0), out)
        np.testing.assert_array_equal(out, numpy_jacobian(x))


@pytest.mark.parametrize("name", sorted(MODELS))
def test_predict_matches_numpy_path(name, random_belief, assert_close):
    motion = MODELS[name]
    compiled = additive_model(motion)
    assert compiled.jacobian_point is motion.jacobian_point
    belief = random_belief(np.random.default_rng(3), motion.n, 24, motion.angle_indices)
    assert takes_compiled_path(belief, compiled, DT_S)
    batched = EKF.predict(belief, compiled, DT_S)
    assert_close(batched, EKF.predict(belief, numpy_twin(compiled), DT_S))
    np.testing.assert_array_equal(batched.cov, batched.cov.mT)
    if motion.angle_indices:
        assert np.abs(batched.mean[:, 2]).max() > 3.0, "headings near +-pi must be exercised"
        assert (batched.mean[:, 2] < math.pi).all() and (batched.mean[:, 2] >= -math.pi).all()
    assert_bitwise_runs(batched, lambda run: EKF.predict(belief[run], compiled, DT_S), (0, 1, 5))
    assert_close(
        EKF.predict(belief[3], compiled, DT_S), EKF.predict(belief[3], numpy_twin(compiled), DT_S)
    )


@pytest.mark.parametrize("measurement", ["pose", "gps"])
def test_update_matches_numpy_path(measurement, random_belief, assert_close):
    motion = MODELS["CTRV"]
    compiled = (
        pose_model(np.diag([0.3, 0.2, 0.05]))
        if measurement == "pose"
        else gps_model(np.diag([0.3, 0.2]))
    )
    rng = np.random.default_rng(5)
    belief = random_belief(rng, motion.n, 24, motion.angle_indices)
    m = compiled.R.shape[0]
    z = belief.mean[:, :m] + rng.normal(size=(24, m)) * 0.3
    if m == 3:
        z[:, 2] = -np.sign(belief.mean[:, 2]) * (math.pi - 0.01)  # the innovation wraps
    assert takes_compiled_path(belief, compiled, z)
    batched = EKF.update(belief, z, compiled)
    reference = EKF.update(belief, z, numpy_twin(compiled))
    assert_close(batched, reference)
    np.testing.assert_array_equal(batched.cov, batched.cov.mT)
    assert np.abs(reference.residual(belief.mean)).max() > 0.01, "the update must move the means"
    assert_bitwise_runs(batched, lambda run: EKF.update(belief[run], z[run], compiled), (0, 7))


@pytest.mark.parametrize("name", ["CTRV", "CCA"])
def test_a_filter_run_matches_the_numpy_filter(name, assert_close):
    """Fifty predict + pose updates of one filter, turning through +-pi: the paths stay within
    rounding of each other (the errors do not grow)."""
    motion = MODELS[name]
    process, measurement = additive_model(motion), pose_model(np.diag([0.09, 0.09, 0.01]))
    rng = np.random.default_rng(13)
    start = np.zeros(motion.n)
    start[2:4] = [3.0, 2.0]
    start[-1] = 0.8 if name == "CTRV" else 0.4
    beliefs = [Gaussian(start, 0.1 * np.eye(motion.n), motion.angle_indices)] * 2
    truth = start
    for _ in range(50):
        truth = motion.transition(truth, DT_S)
        z = truth[:3] + rng.normal(size=3) * [0.3, 0.3, 0.1]
        beliefs = [
            EKF.update(EKF.predict(b, p, DT_S), z, mm)
            for b, p, mm in zip(
                beliefs,
                (process, numpy_twin(process)),
                (measurement, numpy_twin(measurement)),
                strict=True,
            )
        ]
    assert_close(*beliefs)


def test_per_run_arguments_and_noise(random_belief, assert_close):
    motion = MODELS["CTRA"]
    rng = np.random.default_rng(2)
    belief = random_belief(rng, motion.n, 10, motion.angle_indices)
    q_cov = np.einsum("b,ij->bij", rng.uniform(0.5, 2.0, 10), 0.01 * np.eye(motion.n))
    compiled = motion.process_model(q_cov)
    dt = rng.uniform(0.05, 0.2, 10)
    assert takes_compiled_path(belief, compiled, dt)
    predicted = EKF.predict(belief, compiled, dt)
    assert_close(predicted, EKF.predict(belief, numpy_twin(compiled), dt))
    np.testing.assert_array_equal(
        predicted.mean[4],
        EKF.predict(belief[4:5], motion.process_model(q_cov[4:5]), dt[4:5]).mean[0],
    )


def test_iterated_filter_predicts_on_the_compiled_path(random_belief):
    motion = MODELS["CTRV"]
    compiled = additive_model(motion)
    belief = random_belief(np.random.default_rng(6), motion.n, 5, motion.angle_indices)
    iekf = IteratedExtendedKalmanFilter().predict(belief, compiled, DT_S)
    np.testing.assert_array_equal(iekf.mean, EKF.predict(belief, compiled, DT_S).mean)


def test_non_finite_inputs_fall_back_with_the_numpy_errors(random_belief):
    motion = MODELS["CTRV"]
    compiled = additive_model(motion)
    belief = random_belief(np.random.default_rng(8), motion.n, 3, motion.angle_indices)
    assert not takes_compiled_path(belief, compiled, math.nan)
    for model in (compiled, numpy_twin(compiled)):
        with pytest.raises(EstimationError, match="EKF predict: argument 1 is not finite"):
            EKF.predict(belief, model, math.nan)
    mean = np.array(belief.mean)
    mean[1, 3] = math.nan
    broken = Gaussian.trusted(mean, np.array(belief.cov), belief.angle_indices)
    assert not takes_compiled_path(broken, compiled, DT_S)
    for model in (compiled, numpy_twin(compiled)):
        with pytest.raises(
            EstimationError, match=r"EKF predict: the predicted mean .* is not finite"
        ):
            EKF.predict(broken, model, DT_S)
    z = np.zeros((3, 3))
    z[1, 0] = math.inf
    measurement = pose_model(np.eye(3))
    assert not takes_compiled_path(belief, measurement, z)
    for model in (measurement, numpy_twin(measurement)):
        with pytest.raises(EstimationError, match="EKF update: the measurement z is not finite"):
            EKF.update(belief, z, model)
        with pytest.raises(EstimationError, match="has shape"):
            EKF.update(belief, np.zeros((3, 2)), model)
        with pytest.raises(EstimationError, match="EKF update: the updated mean is not finite"):
            EKF.update(broken, np.zeros((3, 3)), model)


def test_non_positive_definite_covariances(random_belief, assert_close):
    """A non-PD ``P`` needs no factor in the EKF: the compiled step takes it and agrees with
    numpy. An ``S`` that is not PD declines, and the numpy step (LU solve) gives the result."""
    motion = MODELS["CTRV"]
    belief = random_belief(np.random.default_rng(4), motion.n, 2, motion.angle_indices)
    cov = np.array(belief.cov)
    cov[1] = np.diag([1.0, 1.0, -1e-3, 1.0, 1.0])
    indefinite = Gaussian(belief.mean, cov, belief.angle_indices)
    compiled = additive_model(motion)
    assert takes_compiled_path(indefinite, compiled, DT_S)
    assert_close(
        EKF.predict(indefinite, compiled, DT_S), EKF.predict(indefinite, numpy_twin(compiled), DT_S)
    )
    cov[1] = np.diag([1.0, 1.0, -1.0, 1.0, 1.0])  # S = P[:3, :3] + R has a negative pivot
    measurement = pose_model(0.01 * np.eye(3))
    broken = Gaussian(belief.mean, cov, belief.angle_indices)
    z = belief.mean[:, :3] + 0.1
    assert not takes_compiled_path(broken, measurement, z)
    updated = EKF.update(broken, z, measurement)
    reference = EKF.update(broken, z, numpy_twin(measurement))
    np.testing.assert_array_equal(updated.mean, reference.mean)
    np.testing.assert_array_equal(updated.cov, reference.cov)


@numba.njit
def damped_point(x, args, out):
    """A user's kernel: ``x' = x * exp(-k dt) + sin(x) dt`` with ``args = (k, dt_s)``."""
    for i in range(x.shape[0]):
        out[i] = x[i] * math.exp(-args[0] * args[1]) + math.sin(x[i]) * args[1]


@numba.njit
def damped_jacobian_point(x, args, out):
    out[:] = 0.0
    for i in range(x.shape[0]):
        out[i, i] = math.exp(-args[0] * args[1]) + math.cos(x[i]) * args[1]


def damped(x, k, dt_s):
    return x * np.exp(-np.asarray(k)[..., None] * dt_s) + np.sin(x) * dt_s


def damped_jacobian(x, k, dt_s):
    diagonal = np.exp(-np.asarray(k)[..., None] * dt_s) + np.cos(x) * dt_s
    return diagonal[..., None] * np.eye(x.shape[-1])


@pytest.mark.slow
def test_user_kernels_are_compiled_once_and_match(assert_close):
    compiled = ProcessModel(
        damped,
        0.01 * np.eye(3),
        jacobian=damped_jacobian,
        point=damped_point,
        jacobian_point=damped_jacobian_point,
    )
    belief = Gaussian(
        np.array([[0.5, -1.0, 2.0], [0.1, 0.2, 0.3]]), np.broadcast_to(0.2 * np.eye(3), (2, 3, 3))
    )
    rates = np.array([0.5, 2.0])  # per run
    assert takes_compiled_path(belief, compiled, rates, DT_S)
    assert_close(
        EKF.predict(belief, compiled, rates, DT_S),
        EKF.predict(belief, numpy_twin(compiled), rates, DT_S),
    )
    entry = compiled_ekf.predict_entry(damped_point, damped_jacobian_point)
    assert compiled_ekf.predict_entry(damped_point, damped_jacobian_point) is entry


def test_kernels_that_do_not_fit_give_one_clear_error():
    @numba.njit
    def two_arguments(x, out):
        out[:] = 0.0

    model = ProcessModel(
        lambda x, dt_s: x,
        np.eye(2),
        jacobian=lambda x, dt_s: np.eye(2),
        point=damped_point,
        jacobian_point=two_arguments,
    )
    with pytest.raises(
        EstimationError, match="EKF predict: the kernel damped_point and two_arguments does not"
    ):
        EKF.predict(Gaussian(np.zeros(2), np.eye(2)), model, 0.5, DT_S)
    with pytest.raises(
        EstimationError, match=r"jacobian_point must be a numba\.njit-compiled function"
    ):
        MeasurementModel(lambda x: x, np.eye(2), jacobian_point=lambda x, args, out: None)


def test_steps_the_compiled_path_cannot_take_use_the_numpy_path(random_belief):
    """Batches of two axes and models without a kernel or the numpy Jacobian go to numpy."""
    motion = MODELS["CV"]
    compiled = additive_model(motion)
    belief = random_belief(np.random.default_rng(9), motion.n, 4, ())
    grid = Gaussian(belief.mean.reshape(2, 2, 4), belief.cov.reshape(2, 2, 4, 4))
    assert not takes_compiled_path(grid, compiled, DT_S)
    np.testing.assert_array_equal(
        EKF.predict(grid, compiled, DT_S).mean, EKF.predict(grid, numpy_twin(compiled), DT_S).mean
    )
    with pytest.raises(EstimationError, match="EKF predict: the model has no jacobian"):
        EKF.predict(belief, dataclasses.replace(compiled, jacobian=None), DT_S)
