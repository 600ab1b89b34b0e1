"""Sigma-point weights and moments against closed forms, including paper 001's alpha = 1e-5."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from localization.errors import EstimationError
from localization.sigma_points import (
    KappaSigmaPoints,
    ScaledSigmaPoints,
    SpreadSigmaPoints,
    cross_covariance,
    sigma_points,
    unscented_moments,
)


def test_weights_match_the_papers_formulas():
    n = 5
    w = ScaledSigmaPoints(alpha=1e-5, beta=2.0, kappa=None).weights(n)  # paper 001 eq. 28
    gamma2 = 1e-10 * (n + 3 - n)
    assert w.gamma**2 == pytest.approx(gamma2)
    assert w.wm0 == pytest.approx((gamma2 - n) / gamma2)
    assert w.cov_weights[0] == pytest.approx((gamma2 - n) / gamma2 + 1 - 1e-10 + 2.0)
    assert w.wi == pytest.approx(1 / (2 * gamma2))
    k = KappaSigmaPoints(kappa=2.0).weights(3)  # paper 000 eq. 1
    assert (
        k.wm0 == pytest.approx(2.0 / 5.0)
        and k.wi == pytest.approx(1 / 10)
        and k.gamma**2 == pytest.approx(5)
    )
    s = SpreadSigmaPoints(a=0.1).weights(3)  # paper 004 eq. 3, 7
    assert s.wm0 == pytest.approx(1 - 100) and s.wi == pytest.approx(1 / (2 * 3 * 0.01))
    assert s.gamma == pytest.approx(0.1 * np.sqrt(3))
    for weights in (w, k, s):
        assert weights.mean_weights.sum() == pytest.approx(
            1.0, abs=1e-12 * abs(weights.wm0) + 1e-15
        )


@pytest.mark.parametrize(
    "make",
    [
        lambda: ScaledSigmaPoints(alpha=0.0),
        lambda: ScaledSigmaPoints(alpha=float("nan")),
        lambda: SpreadSigmaPoints(a=-1.0),
        lambda: KappaSigmaPoints(kappa=-5.0).weights(3),
        lambda: ScaledSigmaPoints(kappa=-3.0).weights(2),
    ],
)
def test_impossible_settings_are_refused(make):
    with pytest.raises(EstimationError):
        make()


@settings(max_examples=30, deadline=None)
@given(
    m=st.floats(-50.0, 50.0),
    p=st.floats(0.01, 4.0),
    alpha=st.sampled_from([1e-5, 1e-3, 0.1, 1.0]),
)
def test_square_of_a_gaussian_exact_mean_and_known_variance(m, p, alpha):
    """y = x^2, x ~ N(m, p): E y = m^2 + p exactly; the scaled UT variance is
    4 m^2 p + (alpha^2 kappa + beta) p^2, i.e. the true 4 m^2 p + 2 p^2 for kappa = 0, beta = 2."""
    weights = ScaledSigmaPoints(alpha=alpha, beta=2.0, kappa=0.0).weights(1)
    points = sigma_points(np.array([m]), np.array([[np.sqrt(p)]]), weights)
    mean, cov, _ = unscented_moments(points**2, weights)
    scale = m * m + p
    # with alpha = 1e-5 the rounding of the deviations is amplified by 1/gamma^2 = 1e10
    tol = 1e-12 * scale / alpha**2 + 1e-12
    assert mean[0] == pytest.approx(m * m + p, abs=tol)
    assert cov[0, 0] == pytest.approx(4 * m * m * p + 2 * p * p, rel=1e-6, abs=tol * (1 + abs(m)))


@settings(max_examples=20, deadline=None)
@given(
    r=st.floats(1.0, 300.0),
    bearing=st.floats(-3.1, 3.1),
    var_r=st.floats(0.01, 10.0),
    var_b=st.floats(1e-4, 0.1),
)
def test_tiny_alpha_polar_to_cartesian_is_psd_and_matches_a_moderate_alpha(
    r, bearing, var_r, var_b
):
    """alpha = 1e-5 (Wm_0 ~ -1e10): the covariance stays PSD (centre form, c0 >= 1) and the mean
    equals the alpha = 1e-3 one up to the finite-difference rounding ~ eps |y| / gamma^2."""

    def polar(p):
        return np.stack([p[..., 0] * np.cos(p[..., 1]), p[..., 0] * np.sin(p[..., 1])], axis=-1)

    mean_x, chol = np.array([r, bearing]), np.diag(np.sqrt([var_r, var_b]))
    results = []
    for alpha in (1e-5, 1e-3):
        weights = ScaledSigmaPoints(alpha=alpha, beta=2.0, kappa=None).weights(2)
        results.append(unscented_moments(polar(sigma_points(mean_x, chol, weights)), weights))
    (mean_tiny, cov_tiny, _), (mean_ref, cov_ref, _) = results
    assert np.linalg.eigvalsh(cov_tiny).min() >= -1e-9 * np.abs(cov_tiny).max()
    np.testing.assert_allclose(mean_tiny, mean_ref, atol=1e-12 * r / 2e-10 + 1e-9)
    np.testing.assert_allclose(cov_tiny, cov_ref, atol=1e-4 * np.abs(cov_ref).max())


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 5), m=st.integers(1, 3))
def test_linear_map_moments_are_exact_for_every_scheme(seed, n, m):
    rng = np.random.default_rng(seed)
    a = rng.standard_normal((m, n))
    mean_x = rng.standard_normal(n)
    root = rng.standard_normal((n, n))
    cov_x = root @ root.T + 0.1 * np.eye(n)
    chol = np.linalg.cholesky(cov_x)
    for scheme in (ScaledSigmaPoints(alpha=0.2), KappaSigmaPoints(), SpreadSigmaPoints(a=0.1)):
        weights = scheme.weights(n)
        points = sigma_points(mean_x, chol, weights)
        mean, cov, dev = unscented_moments(points @ a.T, weights)
        np.testing.assert_allclose(mean, a @ mean_x, atol=1e-9)
        np.testing.assert_allclose(cov, a @ cov_x @ a.T, atol=1e-9)
        np.testing.assert_allclose(cross_covariance(chol, dev, weights), cov_x @ a.T, atol=1e-9)


def test_angle_moments_are_offsets_about_the_centre():
    """Images straddling +-pi average near pi, never near 0 (a raw average would give ~0)."""
    weights = KappaSigmaPoints(kappa=2.0).weights(1)
    points = sigma_points(np.array([np.pi - 0.01]), np.array([[0.1]]), weights)
    images = (points + np.pi) % (2 * np.pi) - np.pi  # some images wrap to about -pi
    assert images.min() < 0 < images.max()
    mean, cov, _ = unscented_moments(images, weights, angle_indices=(0,))
    assert abs(abs(mean[0]) - (np.pi - 0.01)) < 1e-12
    assert cov[0, 0] == pytest.approx(0.01)
    assert -np.pi <= mean[0] < np.pi
