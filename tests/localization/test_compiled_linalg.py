"""The compiled scalar kernels against numpy and the numpy wrapping functions."""

from __future__ import annotations

import math

import numpy as np
import pytest

from localization import linalg
from localization.compiled.linalg import (
    all_finite,
    cholesky_lower,
    cholesky_solve,
    kalman_gain_t,
    wrap_angle,
    wrap_residual,
)


@pytest.mark.parametrize("n", [1, 3, 5, 8])
def test_cholesky_and_solve_match_numpy(n):
    rng = np.random.default_rng(n)
    for _ in range(50):
        root = rng.normal(size=(n, n))
        matrix = root @ root.T + 1e-3 * np.eye(n)
        factor = np.full(
            (n, n), np.nan
        )  # the kernel must overwrite every entry, upper part included
        assert cholesky_lower(matrix, factor)
        np.testing.assert_allclose(factor, np.linalg.cholesky(matrix), rtol=1e-10, atol=1e-12)
        rhs = rng.normal(size=(n, 3))
        out = np.empty_like(rhs)
        cholesky_solve(factor, rhs, out)
        np.testing.assert_allclose(matrix @ out, rhs, rtol=1e-8, atol=1e-8)
        cholesky_solve(factor, rhs, rhs)  # in place gives the same numbers
        np.testing.assert_array_equal(rhs, out)


def test_cholesky_reads_the_lower_triangle_only():
    matrix = np.array([[4.0, 99.0], [2.0, 3.0]])  # the upper entry is garbage
    factor = np.empty((2, 2))
    assert cholesky_lower(matrix, factor)
    np.testing.assert_allclose(factor, np.linalg.cholesky(np.array([[4.0, 2.0], [2.0, 3.0]])))


@pytest.mark.parametrize(
    "matrix",
    [
        np.array([[1.0, 2.0], [2.0, 1.0]]),  # indefinite
        np.array([[1.0, 1.0], [1.0, 1.0]]),  # singular: the second pivot is exactly 0
        np.array([[-1.0, 0.0], [0.0, 1.0]]),
        np.array([[np.nan, 0.0], [0.0, 1.0]]),
        np.array([[np.inf, 0.0], [0.0, 1.0]]),
    ],
)
def test_cholesky_refuses_what_lapack_refuses(matrix):
    assert not cholesky_lower(matrix, np.empty((2, 2)))
    with pytest.raises(np.linalg.LinAlgError):
        np.linalg.cholesky(np.where(np.isfinite(matrix), matrix, -1.0))


def test_wrapping_matches_the_numpy_functions():
    rng = np.random.default_rng(1)
    angles = np.concatenate(
        [
            rng.uniform(-50.0, 50.0, 2000),
            [
                -math.pi,
                math.pi,
                np.nextafter(-math.pi, -4.0),
                np.nextafter(math.pi, 4.0),
                0.0,
                3 * math.pi,
                -3 * math.pi,
                # the fast path (no modulo) where the shift by pi loses the angle's low bits
                1e-20,
                -1e-20,
                -0.0,
                np.nextafter(math.pi, 0.0),
                np.nextafter(-math.pi, 0.0),
            ],
        ]
    )
    wrapped = np.array([wrap_angle(a) for a in angles])
    np.testing.assert_array_equal(wrapped, linalg.wrap_angle(angles))
    assert wrapped.min() >= -math.pi and wrapped.max() < math.pi
    assert math.isnan(wrap_angle(math.nan)) and math.isnan(wrap_angle(math.inf))
    residuals = np.array([wrap_residual(a) for a in angles])
    np.testing.assert_array_equal(residuals, linalg.wrap_residual(angles))


def test_all_finite():
    # values whose sum overflows are finite all the same
    for values in (np.zeros((3, 4)), np.full(3, 1.7e308), np.full((2, 2), -1.7e308)):
        assert all_finite(values)
        for bad in (np.nan, np.inf, -np.inf):
            changed = values.copy()
            changed.flat[-1] = bad
            assert not all_finite(changed)
    assert all_finite(np.zeros(0))


@pytest.mark.parametrize(("n", "m"), [(5, 3), (8, 3), (4, 2)])
def test_kalman_gain_matches_the_textbook_gain(n, m):
    rng = np.random.default_rng(10 * n + m)
    for _ in range(30):
        root = rng.normal(size=(n, n))
        cov = root @ root.T + 1e-2 * np.eye(n)
        jac = rng.normal(size=(m, n))
        noise = np.diag(rng.uniform(0.01, 1.0, m))
        cross, s_cov, s_chol, gain_t = (
            np.empty((n, m)),
            np.empty((m, m)),
            np.empty((m, m)),
            np.empty((m, n)),
        )
        assert kalman_gain_t(cov, jac, noise, cross, s_cov, s_chol, gain_t)
        expected = cov @ jac.T @ np.linalg.inv(jac @ cov @ jac.T + noise)
        np.testing.assert_allclose(gain_t.T, expected, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(s_cov, jac @ cov @ jac.T + noise, rtol=1e-12)
    # S not positive definite (a negative noise variance larger than H P H^T): refused
    assert not kalman_gain_t(
        np.eye(2),
        np.eye(2),
        -2.0 * np.eye(2),
        np.empty((2, 2)),
        np.empty((2, 2)),
        np.empty((2, 2)),
        np.empty((2, 2)),
    )


def test_numpy_wrap_keeps_the_half_open_range_beside_a_nan():
    """A NaN in the array made the numpy wrap skip its edge fix for every element (its
    maximum was NaN): the angle just below -pi then came out as +pi."""
    from localization.linalg import wrap_angle as numpy_wrap

    below = np.nextafter(-np.pi, -4.0)
    alone = numpy_wrap(np.array([below]))
    beside = numpy_wrap(np.array([np.nan, below]))
    assert np.isnan(beside[0]) and beside[1] == alone[0]
    assert -np.pi <= beside[1] < np.pi
