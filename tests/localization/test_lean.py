"""The lean filters (localization.compiled.lean): the filters' own steps bit for bit, a linear
Kalman filter written here on a linear case, and their refusals."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numba
import numpy as np
import pytest

from localization.compiled import lean as lean_module
from localization.compiled.lean import LeanEKF, LeanUKF
from localization.ekf import ExtendedKalmanFilter
from localization.errors import EstimationError
from localization.gaussian import Gaussian
from localization.models import ProcessModel, ProcessNoise
from localization.motion_models import CV, MODELS, gps_model, pose_model
from localization.sigma_points import ScaledSigmaPoints
from localization.ukf import UnscentedKalmanFilter

DT_S = 0.1
UKF = UnscentedKalmanFilter(ScaledSigmaPoints(alpha=0.5))
START = {
    "CV": np.array([1.0, -2.0, 3.0, 1.0]),
    "CTRV": np.array([1.0, -2.0, 3.0, 5.0, 0.4]),
    "CTRA": np.array([1.0, -2.0, 3.0, 5.0, 0.5, 0.4]),
    "CCA": np.array([1.0, -2.0, 3.0, 5.0, 0.5, 0.05]),
}


def _problem(name: str, noise: ProcessNoise, steps: int = 30, seed: int = 0):
    """A model's ``(process, measurement, belief, zs (steps, m))``: a truth propagated by the
    model with small perturbations, measured with noise (pose, GPS for CV)."""
    model = MODELS[name]
    rng = np.random.default_rng(seed)
    n = model.n
    if noise == ProcessNoise.AUGMENTED:
        process = model.process_model(np.diag(model.process_noise_std(DT_S) ** 2), noise)
    else:
        process = model.process_model(np.diag(np.full(n, 1e-3)))
    measurement = (
        gps_model(np.eye(2) * 0.25) if name == "CV" else pose_model(np.diag([0.25, 0.25, 0.01]))
    )
    m = measurement.R.shape[0]
    truth, zs = START[name].copy(), np.empty((steps, m))
    for t in range(steps):
        truth = model.transition(truth, DT_S) + rng.normal(size=n) * 1e-3
        zs[t] = truth[:m] + rng.normal(size=m) * np.sqrt(np.diag(measurement.R))
    belief = Gaussian(START[name] + 0.1, np.diag(np.full(n, 0.5)), model.angle_indices)
    return process, measurement, belief, zs


CASES = [(name, ProcessNoise.ADDITIVE) for name in MODELS] + [
    (name, ProcessNoise.AUGMENTED) for name in MODELS
]


@pytest.mark.parametrize(("name", "noise"), CASES)
def test_lean_ukf_steps_are_the_filters_steps_bit_for_bit(name, noise):
    process, measurement, belief, zs = _problem(name, noise)
    lean = LeanUKF(UKF, process, measurement, belief, DT_S)
    means, covs = LeanUKF(UKF, process, measurement, belief, DT_S).run(zs)
    for t, z in enumerate(zs):
        belief = UKF.update(UKF.predict(belief, process, DT_S), z, measurement)
        lean.step(z)
        assert np.array_equal(lean.mean, belief.mean) and np.array_equal(lean.cov, belief.cov), t
        assert np.array_equal(means[t], belief.mean) and np.array_equal(covs[t], belief.cov), t
    assert lean.belief.angle_indices == belief.angle_indices


@pytest.mark.parametrize("name", list(MODELS))
def test_lean_ekf_steps_are_the_filters_steps_bit_for_bit(name):
    ekf = ExtendedKalmanFilter()
    process, measurement, belief, zs = _problem(name, ProcessNoise.ADDITIVE, seed=1)
    lean = LeanEKF(process, measurement, belief, DT_S)
    means, covs = LeanEKF(process, measurement, belief, DT_S).run(zs)
    for t, z in enumerate(zs):
        belief = ekf.update(ekf.predict(belief, process, DT_S), z, measurement)
        lean.step(z)
        assert np.array_equal(lean.mean, belief.mean) and np.array_equal(lean.cov, belief.cov), t
        assert np.array_equal(means[t], belief.mean) and np.array_equal(covs[t], belief.cov), t


def _linear_kalman_filter(x, P, zs, Q, R):
    """The textbook Kalman filter of the constant-velocity model ``x = (px, py, vx, vy)``,
    position measured: ``F = [[I, dt I], [0, I]]``, ``H = [I 0]``, written out here."""
    F = np.block([[np.eye(2), DT_S * np.eye(2)], [np.zeros((2, 2)), np.eye(2)]])
    H = np.hstack([np.eye(2), np.zeros((2, 2))])
    means, covs = [], []
    for z in zs:
        x, P = F @ x, F @ P @ F.T + Q
        S = H @ P @ H.T + R
        K = P @ H.T @ np.linalg.inv(S)
        x = x + K @ (z - H @ x)
        P = (np.eye(4) - K @ H) @ P
        means.append(x)
        covs.append(P)
    return np.array(means), np.array(covs)


def test_lean_filters_are_the_linear_kalman_filter_on_a_linear_model():
    Q = np.diag([1e-3, 2e-3, 0.05, 0.04]) + 1e-4
    R = np.array([[0.3, 0.05], [0.05, 0.2]])
    process, measurement = CV.process_model(Q), gps_model(R)
    rng = np.random.default_rng(3)
    zs = np.cumsum(rng.normal(size=(50, 2)), axis=0)
    belief = Gaussian(np.array([0.0, 0.0, 1.0, -1.0]), np.diag([2.0, 2.0, 1.0, 1.0]))
    expected_means, expected_covs = _linear_kalman_filter(belief.mean, belief.cov, zs, Q, R)
    for lean in (
        LeanUKF(UKF, process, measurement, belief, DT_S),
        LeanEKF(process, measurement, belief, DT_S),
    ):
        means, covs = lean.run(zs)
        # the UKF is exact on a linear model: the two differ by rounding only
        np.testing.assert_allclose(means, expected_means, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(covs, expected_covs, rtol=1e-12, atol=1e-12)


def test_a_failed_step_raises_and_keeps_the_state_before_it():
    process, measurement, belief, zs = _problem("CTRV", ProcessNoise.ADDITIVE)
    lean = LeanUKF(UKF, process, measurement, belief, DT_S)
    lean.step(zs[0])
    mean, cov = lean.mean.copy(), lean.cov.copy()
    with pytest.raises(EstimationError, match="not finite"):
        lean.step(np.array([np.nan, 0.0, 0.0]))
    assert np.array_equal(lean.mean, mean) and np.array_equal(lean.cov, cov)

    bad = zs.copy()
    bad[4, 1] = np.inf
    reference = LeanUKF(UKF, process, measurement, belief, DT_S)
    reference.run(zs[:4])
    again = LeanUKF(UKF, process, measurement, belief, DT_S)
    with pytest.raises(EstimationError, match="at step 4"):
        again.run(bad)
    assert np.array_equal(again.mean, reference.mean) and np.array_equal(again.cov, reference.cov)

    flat = Gaussian(belief.mean, np.diag([1.0, 1.0, 0.0, 1.0, 1.0]), belief.angle_indices)
    singular = LeanEKF(process, measurement, flat, DT_S)
    singular.step(zs[0])  # the EKF needs no factor of P: a singular P is fine
    with pytest.raises(EstimationError, match="not positive definite"):
        LeanUKF(UKF, process, measurement, flat, DT_S).step(zs[0])


def test_the_lean_filters_refuse_what_they_cannot_run():
    process, measurement, belief, zs = _problem("CTRV", ProcessNoise.ADDITIVE)
    numpy_only = ProcessModel(MODELS["CTRV"].transition, process.Q)
    with pytest.raises(EstimationError, match="built-in motion model"):
        LeanUKF(UKF, numpy_only, measurement, belief, DT_S)
    augmented = MODELS["CTRV"].process_model(np.eye(2) * 1e-2, ProcessNoise.AUGMENTED)
    with pytest.raises(EstimationError, match="built-in motion model"):
        LeanEKF(augmented, measurement, belief, DT_S)
    with pytest.raises(EstimationError, match="5 states, the process model 4"):
        LeanUKF(UKF, CV.process_model(np.eye(4)), measurement, belief, DT_S)
    batch = Gaussian(np.stack([belief.mean] * 2), np.stack([belief.cov] * 2), (2,))
    with pytest.raises(EstimationError, match="one run"):
        LeanUKF(UKF, process, measurement, batch, DT_S)
    with pytest.raises(EstimationError, match="finite numbers"):
        LeanUKF(UKF, process, measurement, belief, float("nan"))
    lean = LeanUKF(UKF, process, measurement, belief, DT_S)
    with pytest.raises(EstimationError, match=r"shape \(3,\), got \(2,\)"):
        lean.step(np.zeros(2))  # checked by the compiled step
    with pytest.raises(EstimationError, match=r"shape \(3,\), got \(4,\)"):
        lean.step(np.zeros(8)[::2])  # refused by the entry, then checked
    with pytest.raises(EstimationError, match=r"shape \(3,\), got \(1, 3\)"):
        lean.step(zs[:1])
    with pytest.raises(EstimationError, match=r"shape \(T, 3\)"):
        lean.run(zs[:, :2])
    lean.step([float(v) for v in zs[0]])  # a list is taken as an array
    with pytest.raises(ValueError):
        lean.mean[0] = 1.0  # the views are read-only


# The end of the views only: the views are borrowed (``compiled.batch.borrow``), not for Python.
_UKF_WORK_END = numba.njit(lambda work, layout: lean_module.ukf_views(work, layout)[-1])
_EKF_WORK_END = numba.njit(lambda work, layout: lean_module.ekf_views(work, layout)[-1])


@pytest.mark.parametrize(("name", "noise"), CASES)
def test_the_work_array_is_carved_to_its_last_entry(name, noise):
    """The Python length of the work array and the compiled views of it agree: the views tile
    it, none past its end and none short of it."""
    process, measurement, belief, _ = _problem(name, noise)
    filters: list[LeanUKF | LeanEKF] = [LeanUKF(UKF, process, measurement, belief, DT_S)]
    if noise == ProcessNoise.ADDITIVE:
        filters.append(LeanEKF(process, measurement, belief, DT_S))
    for lean in filters:
        end = _UKF_WORK_END if isinstance(lean, LeanUKF) else _EKF_WORK_END
        assert end(lean._work, lean._layout) == lean._work.shape[0], type(lean).__name__


def _refused_measurements(z: np.ndarray) -> dict[str, object]:
    """``z (3,)`` as the measurements a step entry is not compiled for (``_sealed``)."""
    wide = np.zeros((3, 2))
    wide[:, 0] = z
    read_only = z.copy()
    read_only.flags.writeable = False
    return {
        "strided": wide[:, 0],
        "read-only": read_only,
        "float32": z.astype(np.float32),
        "int64": np.round(z).astype(np.int64),
        "list": [float(v) for v in z],
    }


def test_a_measurement_of_another_type_is_copied_not_compiled_for():
    """A step given a strided, read-only, float32 or integer ``z`` (or a list) takes a copy,
    with the results of a plain ``z``, and numba compiles nothing new: the entries keep the
    one signature they were sealed with."""
    process, measurement, belief, zs = _problem("CTRV", ProcessNoise.ADDITIVE)
    for cls, args in ((LeanUKF, (UKF, process)), (LeanEKF, (process,))):
        entry = cls._step_entry
        for name, z in _refused_measurements(zs[0]).items():
            lean = cls(*args, measurement, belief, DT_S)
            plain = cls(*args, measurement, belief, DT_S)
            lean.step(z)
            plain.step(np.array(z, dtype=np.float64))
            assert np.array_equal(lean.mean, plain.mean), (cls.__name__, name)
            assert np.array_equal(lean.cov, plain.cov), (cls.__name__, name)
        assert len(entry.signatures) == 1, entry.signatures
        with pytest.raises(TypeError):
            entry(lean._work, zs[:, 0], lean._layout)  # the entry itself refuses


ALLOCATIONS = """
import numba
import numpy as np
from numba.core.runtime import rtsys

from localization.compiled.lean import LeanEKF, LeanUKF
from localization.gaussian import Gaussian
from localization.motion_models import CTRV, pose_model
from localization.ukf import UnscentedKalmanFilter

ukf = UnscentedKalmanFilter()
process, measurement = CTRV.process_model(np.eye(5) * 1e-3), pose_model(np.eye(3) * 0.1)
belief = Gaussian(np.array([1.0, 2.0, 0.3, 4.0, 0.1]), np.eye(5), (2,))
z = np.array([1.0, 2.0, 0.3])


@numba.njit
def nothing(work, z, layout):
    return 0


def allocations(step):
    step()  # compiled (or loaded) before counting
    before = rtsys.get_allocation_stats().alloc
    for _ in range(10):
        step()
    return rtsys.get_allocation_stats().alloc - before


lean_ukf = LeanUKF(ukf, process, measurement, belief, 0.01)
lean_ekf = LeanEKF(process, measurement, belief, 0.01)
print(
    allocations(lambda: nothing(lean_ukf._work, z, lean_ukf._layout)),
    allocations(lambda: lean_ukf.step(z)),
    allocations(lambda: lean_ekf.step(z)),
    allocations(lambda: lean_ukf.run(np.tile(z, (1, 1)))),
    allocations(lambda: lean_ukf.run(np.tile(z, (50, 1)))),
    allocations(lambda: ukf.update(ukf.predict(belief, process, 0.01), z, measurement)),
)
"""


@pytest.mark.slow
def test_a_lean_step_allocates_nothing():
    """numba's runtime counts its allocations when ``NUMBA_NRT_STATS`` is set (in a new
    process). Calling a compiled function wraps each array argument (one count each): a lean
    step counts what a function doing nothing with the same arguments counts, a run of 50
    steps what a run of one counts; the filter's compiled step (the control) more."""
    root = Path(__file__).resolve().parents[2]
    done = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(ALLOCATIONS)],
        capture_output=True,
        text=True,
        env={**os.environ, "PYTHONPATH": str(root), "NUMBA_NRT_STATS": "1"},
        timeout=900,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    nothing, ukf_step, ekf_step, run_1, run_50, filter_step = map(int, done.stdout.split())
    assert ukf_step == ekf_step == nothing
    assert run_50 == run_1
    assert filter_step > nothing
