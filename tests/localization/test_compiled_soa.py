"""The structure-of-arrays batched UKF (localization.compiled.soa) against the per-run path.

The reference is the loop of :mod:`localization.compiled.batch` over the per-run functions of
:mod:`localization.compiled.ukf` (what a lean filter steps, one run at a time): the SoA
entries must give its means, covariances and status bit for bit, for every built-in motion
model, both noise kinds, both measurement models, shared and per-run noise and arguments, and
batches that end inside a block.
"""

from __future__ import annotations

import numpy as np
import pytest

from localization.compiled import soa
from localization.compiled.glue import NOT_FINITE, NOT_POSITIVE_DEFINITE, OK, angle_array
from localization.reference.per_run_ukf import (
    per_run_augmented,
    per_run_predict,
    per_run_update,
)
from localization.sigma_points import ScaledSigmaPoints

DIMENSIONS = {0: 4, 1: 5, 2: 6, 3: 6}  # CV, CTRV, CTRA, CCA
HEADING = {0: (), 1: (2,), 2: (2,), 3: (2,)}
RUNS = 2 * soa.RUN_BLOCK + 13  # two full blocks and a part
POINTS = ScaledSigmaPoints(alpha=0.3)


def _read_only(values) -> np.ndarray:
    values = np.array(values, dtype=np.float64, order="C")
    values.flags.writeable = False
    return values


def _beliefs(n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Random means (headings beyond pi, so that they wrap) and covariances of ``RUNS`` runs."""
    mean = rng.normal(size=(RUNS, n)) * np.array([5.0, 5.0, 4.0] + [1.0] * (n - 3))
    spread = rng.normal(size=(RUNS, n, n)) * 0.3
    cov = spread @ spread.transpose(0, 2, 1) + 0.01 * np.eye(n)
    return mean, cov


def _both(reference, entry, runs_n: tuple[int, int], *arguments):
    """``(status, mean, cov)`` of the reference and of the SoA entry on the same inputs, the
    outputs ``(runs, n)``, ``(runs, n, n)`` filled with a sentinel first."""
    results = []
    for function in (reference, entry):
        runs, n = runs_n
        outs = (np.full((runs, n), -7.0), np.full((runs, n, n), -7.0))
        results.append((function(*arguments, *outs), *outs))
    return results


def _predict_arguments(model: int, augmented: bool, per_run: bool, rng, mean, cov):
    n = DIMENSIONS[model]
    q = 2 if augmented else n
    noise = np.eye(q) * (0.2 if augmented else 0.05) + 0.01
    if augmented:
        noise = np.linalg.cholesky(noise)  # the square root S S^T = Q
    runs = RUNS if per_run else 1
    noise = noise * rng.uniform(0.5, 1.5, (runs, 1, 1))
    args = rng.uniform(0.05, 0.5, (runs, 1))
    weights = POINTS.weights(n + q if augmented else n).packed
    return (
        _read_only(mean),
        _read_only(cov),
        _read_only(args),
        _read_only(noise),
        weights,
        angle_array(HEADING[model]),
    )


def _predict_pair(model: int, augmented: bool):
    return (
        (per_run_augmented, soa.noisy_predict_builtin)
        if augmented
        else (per_run_predict, soa.predict_builtin)
    )


@pytest.mark.parametrize("per_run", [False, True], ids=["shared", "per-run"])
@pytest.mark.parametrize("augmented", [False, True], ids=["additive", "augmented"])
@pytest.mark.parametrize("model", [0, 1, 2, 3], ids=["CV", "CTRV", "CTRA", "CCA"])
def test_prediction_is_the_per_run_path_bit_for_bit(model, augmented, per_run):
    rng = np.random.default_rng(17 + model)
    mean, cov = _beliefs(DIMENSIONS[model], rng)
    arguments = _predict_arguments(model, augmented, per_run, rng, mean, cov)
    reference, entry = _predict_pair(model, augmented)
    (status, ref_mean, ref_cov), (soa_status, soa_mean, soa_cov) = _both(
        reference, entry, mean.shape, model, *arguments
    )
    assert status == soa_status == OK
    np.testing.assert_array_equal(soa_mean, ref_mean)
    np.testing.assert_array_equal(soa_cov, ref_cov)
    assert not np.array_equal(soa_mean, mean)  # the step moved the states


def _update_arguments(n: int, m: int, per_run: bool, rng, mean, cov):
    runs = RUNS if per_run else 1
    r_cov = (np.eye(m) * 0.1 + 0.02) * rng.uniform(0.5, 1.5, (runs, 1, 1))
    z = mean[:, :m] + rng.normal(size=(RUNS, m))
    if m == 3:
        z[:, 2] += 2.0 * np.pi * rng.integers(-2, 3, RUNS)  # headings to wrap
    return (
        _read_only(mean),
        _read_only(cov),
        np.array(z),
        _read_only(np.empty((1, 0))),
        _read_only(r_cov),
        POINTS.weights(n).packed,
        angle_array((2,) if n > 4 else ()),
        angle_array((2,) if m == 3 else ()),
    )


@pytest.mark.parametrize("per_run", [False, True], ids=["shared", "per-run"])
@pytest.mark.parametrize(("n", "m"), [(4, 2), (5, 2), (5, 3), (6, 3)], ids=str)
def test_update_is_the_per_run_path_bit_for_bit(n, m, per_run):
    rng = np.random.default_rng(100 * n + m)
    mean, cov = _beliefs(n, rng)
    arguments = _update_arguments(n, m, per_run, rng, mean, cov)
    (status, ref_mean, ref_cov), (soa_status, soa_mean, soa_cov) = _both(
        per_run_update, soa.update_leading_entries, mean.shape, *arguments
    )
    assert status == soa_status == OK
    np.testing.assert_array_equal(soa_mean, ref_mean)
    np.testing.assert_array_equal(soa_cov, ref_cov)
    assert not np.array_equal(soa_cov, cov)  # the update shrank the covariances


def _not_positive_definite(n: int) -> np.ndarray:
    """A symmetric matrix with a negative pivot at its last entry (earlier pivots positive)."""
    matrix = np.eye(n)
    matrix[-1, -1] = -1e-3
    return matrix


@pytest.mark.parametrize("augmented", [False, True], ids=["additive", "augmented"])
def test_a_bad_run_gives_the_status_of_the_per_run_path(augmented):
    model, rng = 1, np.random.default_rng(5)
    mean, cov = _beliefs(DIMENSIONS[model], rng)
    reference, entry = _predict_pair(model, augmented)

    def statuses(mean, cov):
        arguments = _predict_arguments(model, augmented, False, rng, mean, cov)
        both = _both(reference, entry, mean.shape, model, *arguments)
        return both[0][0], both[1][0]

    late, early = soa.RUN_BLOCK + 5, soa.RUN_BLOCK + 3  # in the second block
    bad_cov = cov.copy()
    bad_cov[late] = _not_positive_definite(5)
    assert statuses(mean, bad_cov) == (NOT_POSITIVE_DEFINITE,) * 2
    bad_mean = mean.copy()
    bad_mean[early, 3] = np.inf  # P fine, the result not finite, before the bad P
    assert statuses(bad_mean, bad_cov) == (NOT_FINITE,) * 2
    bad_mean[early, 3] = mean[early, 3]
    bad_mean[RUNS - 1, 0] = np.nan  # after the bad P, in the part block
    assert statuses(bad_mean, bad_cov) == (NOT_POSITIVE_DEFINITE,) * 2
    assert statuses(bad_mean, cov) == (NOT_FINITE,) * 2
    bad_cov = cov.copy()
    bad_cov[0, 0, 0] = 0.0  # a zero pivot: divides (no exception), reported
    assert statuses(mean, bad_cov) == (NOT_POSITIVE_DEFINITE,) * 2


def test_a_bad_run_of_an_update_gives_the_status_of_the_per_run_path():
    n, m, rng = 5, 3, np.random.default_rng(6)
    mean, cov = _beliefs(n, rng)

    def statuses(cov, z_bad=None, r_bad=None):
        arguments = list(_update_arguments(n, m, True, rng, mean, cov))
        if z_bad is not None:
            arguments[2][z_bad, 1] = np.nan
        if r_bad is not None:
            r_cov = np.array(arguments[4])
            r_cov[r_bad] = -10.0 * np.eye(m)  # S = (moments) + R not positive definite
            arguments[4] = _read_only(r_cov)
        both = _both(per_run_update, soa.update_leading_entries, mean.shape, *arguments)
        return both[0][0], both[1][0]

    assert statuses(cov) == (OK, OK)
    bad_cov = cov.copy()
    bad_cov[soa.RUN_BLOCK + 9] = _not_positive_definite(n)
    assert statuses(bad_cov) == (NOT_POSITIVE_DEFINITE,) * 2
    assert statuses(cov, r_bad=40) == (NOT_POSITIVE_DEFINITE,) * 2
    assert statuses(bad_cov, z_bad=soa.RUN_BLOCK + 9) == (NOT_FINITE,) * 2  # z checked first
    assert statuses(bad_cov, z_bad=RUNS - 1) == (NOT_POSITIVE_DEFINITE,) * 2
