"""Long batches are stepped in slices of runs: the numbers must not change by a single bit."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

import localization.ukf as ukf_module
from localization.errors import EstimationError
from localization.gaussian import Gaussian
from localization.models import MeasurementModel, ProcessModel
from localization.motion_models import CTRV
from localization.sigma_points import ScaledSigmaPoints
from localization.ukf import SLICE_RUNS, UnscentedKalmanFilter, run_slices

RUNS = 2 * SLICE_RUNS + 7  # three slices, the last ones uneven


def transition_with_speed_noise(x, w, dt):
    """CTRV with a noise ``w (..., 2)`` added to the speed and the turn rate (augmented form)."""
    return CTRV.transition_with_noise(x, w, dt)


ADDITIVE = ProcessModel(CTRV.transition, np.diag([1e-4, 1e-4, 1e-4, 1e-2, 1e-3]))
AUGMENTED = ProcessModel(transition_with_speed_noise, np.diag([1e-2, 1e-3]), noise="augmented")
POSE = MeasurementModel(lambda x: x[..., :3], np.diag([0.04, 0.04, 0.01]), angle_indices=(2,))


def problem(seed):
    rng = np.random.default_rng(seed)
    mean = np.column_stack(
        [
            rng.normal(0.0, 5.0, (RUNS, 2)),
            rng.uniform(-np.pi, np.pi, RUNS),
            rng.uniform(0.5, 3.0, RUNS),
            rng.normal(0, 0.5, RUNS),
        ]
    )
    roots = rng.normal(0.0, 0.1, (RUNS, 5, 5))
    cov = roots @ roots.mT + 1e-3 * np.eye(5)
    dts = rng.uniform(0.05, 0.2, RUNS)  # a per-run argument: sliced with the runs
    z = mean[:, :3] + rng.normal(0.0, 0.1, (RUNS, 3))
    return Gaussian(mean, cov, angle_indices=(2,)), dts, z


def two_steps(process, belief, dts, z):
    ukf = UnscentedKalmanFilter(ScaledSigmaPoints(alpha=1e-3))
    for _ in range(2):
        belief = ukf.update(ukf.predict(belief, process, dts), z, POSE)
    return belief


@pytest.mark.parametrize("process", [ADDITIVE, AUGMENTED], ids=["additive", "augmented"])
def test_sliced_batch_equals_the_batch_in_one_piece_and_the_runs_one_by_one(process, monkeypatch):
    belief, dts, z = problem(1)
    sliced = two_steps(process, belief, dts, z)
    monkeypatch.setattr(ukf_module, "SLICE_RUNS", 10 * RUNS)
    whole = two_steps(process, belief, dts, z)
    np.testing.assert_array_equal(sliced.mean, whole.mean)
    np.testing.assert_array_equal(sliced.cov, whole.cov)
    for i in (0, SLICE_RUNS - 1, SLICE_RUNS, RUNS - 1):  # both sides of the slice edges
        alone = two_steps(process, belief[i], dts[i], z[i])
        np.testing.assert_allclose(sliced.mean[i], alone.mean, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(sliced.cov[i], alone.cov, rtol=1e-12, atol=1e-12)


def test_slices_cover_the_batch_evenly_and_only_when_they_can():
    parts = run_slices((RUNS,), np.eye(2))
    sizes = [p.stop - p.start for p in parts]
    assert parts[0].start == 0 and parts[-1].stop == RUNS
    assert all(a.stop == b.start for a, b in itertools.pairwise(parts))
    assert max(sizes) <= SLICE_RUNS and max(sizes) - min(sizes) <= 1
    assert run_slices((SLICE_RUNS,), np.eye(2)) is None  # short enough
    assert run_slices((RUNS,), np.broadcast_to(np.eye(2), (RUNS, 2, 2))) is None  # per-run noise
    assert run_slices((3, RUNS), np.eye(2)) is None  # not a flat batch


def test_a_measurement_of_the_wrong_shape_is_refused_for_the_whole_batch():
    belief, _, z = problem(2)
    ukf = UnscentedKalmanFilter()
    with pytest.raises(EstimationError, match=rf"shape \({RUNS + 1}, 3\), expected \({RUNS}, 3\)"):
        ukf.update(belief, np.concatenate([z, z[:1]]), POSE)
    with pytest.raises(EstimationError, match=rf"shape \({RUNS}, 2\), expected \({RUNS}, 3\)"):
        ukf.update(belief, z[:, :2], POSE)
