"""NEES of ``scenarios.metrics`` against filters whose consistency is known by construction."""

from __future__ import annotations

import numpy as np
from scipy import stats

from scenarios.metrics import consistency_stats, nees, nees_band, nees_stats

RUNS = 4000


def linear_kalman_final(rng: np.random.Generator, steps: int, q: float, r: float):
    """``RUNS`` independent runs of a 2-state random walk ``x_{k+1} = x_k + w`` (``w ~ N(0, q I)``)
    seen through ``z = x + v`` (``v ~ N(0, r I)``), filtered by the textbook Kalman filter:
    the final truths, estimates ``(RUNS, 2)`` and covariances ``(RUNS, 2, 2)``."""
    eye = np.eye(2)
    x = np.zeros((RUNS, 2))
    estimate = np.zeros((RUNS, 2))
    p = np.broadcast_to(eye, (RUNS, 2, 2)).copy()
    x += rng.multivariate_normal(np.zeros(2), eye, size=RUNS)  # truth drawn from the prior
    for _ in range(steps):
        x += rng.normal(0.0, np.sqrt(q), size=(RUNS, 2))
        p = p + q * eye
        z = x + rng.normal(0.0, np.sqrt(r), size=(RUNS, 2))
        gain = p @ np.linalg.inv(p + r * eye)
        estimate = estimate + np.einsum("nij,nj->ni", gain, z - estimate)
        p = (eye - gain) @ p
    return x, estimate, p


def test_nees_of_a_linear_kalman_filter_is_chi_square_with_its_state_dimension():
    """Over independent runs the NEES of a correct Kalman filter is chi-square(2): mean 2
    (standard error sqrt(4 / RUNS)), 95 % of samples inside the band; a filter claiming a
    quarter of its true covariance is flagged (mean about 8, far fewer inside)."""
    truth, estimate, p = linear_kalman_final(np.random.default_rng(7), steps=20, q=0.1, r=0.5)
    values = nees(estimate, p, truth)
    assert abs(values.mean() - 2.0) < 4 * np.sqrt(4.0 / RUNS)
    summary = nees_stats(values, 2)
    assert abs(summary["share_in_band"] - 0.95) < 4 * np.sqrt(0.95 * 0.05 / RUNS)
    assert stats.kstest(values, stats.chi2(2).cdf).pvalue > 1e-3

    overconfident = nees_stats(nees(estimate, p / 4.0, truth), 2)
    assert abs(overconfident["mean"] - 8.0) < 1.0
    assert overconfident["share_in_band"] < 0.8 and overconfident["share_above"] > 0.2


def test_pose_nees_wraps_the_heading_error_and_matches_the_quadratic_form():
    """Poses whose heading straddles +-pi: the NEES is ``e^T P^-1 e`` of the wrapped error,
    computed here with an explicit inverse; the unwrapped error would be about 2 pi off."""
    rng = np.random.default_rng(3)
    n = 500
    a = rng.normal(size=(n, 3, 3))
    cov = a @ a.swapaxes(1, 2) * 0.01 + 1e-3 * np.eye(3)
    truth = np.column_stack([rng.uniform(0, 5, n), rng.uniform(0, 5, n), np.full(n, np.pi - 1e-3)])
    error = np.einsum("nij,nj->ni", np.linalg.cholesky(cov), rng.normal(size=(n, 3)))
    estimate = truth + error
    estimate[:, 2] = (estimate[:, 2] + np.pi) % (2 * np.pi) - np.pi  # written in [-pi, pi)
    expected = np.einsum("ni,nij,nj->n", error, np.linalg.inv(cov), error)
    np.testing.assert_allclose(nees(estimate, cov, truth), expected, rtol=1e-9)


def test_band_is_the_chi_square_quantiles_and_branches_are_reported_apart():
    low, high = nees_band(3)
    assert np.isclose(stats.chi2.cdf(low, 3), 0.025) and np.isclose(stats.chi2.cdf(high, 3), 0.975)
    truth = np.zeros((50, 3))
    pose = np.stack([truth + 0.1, truth + 0.3])
    cov = np.broadcast_to(0.01 * np.eye(3), (2, 50, 3, 3))
    result = consistency_stats(pose, cov, truth, ("a", "b"))
    assert np.isclose(result["a"]["pose"]["mean"], 3.0)
    assert np.isclose(result["b"]["pose"]["mean"], 27.0)
    assert np.isclose(result["b"]["position"]["mean"], 18.0)
    assert result["b"]["pose"]["share_above"] == 1.0
