"""Fixtures shared by the test packages.

Helpers that several test modules call are fixtures here (a module never imports another
test module). A helper that other plain helper functions call cannot be a fixture; those
live in :mod:`tests.helpers`.

Markers (pyproject.toml): ``slow`` marks the compile-heavy, subprocess and long statistical
tests; ``pytest -m "not slow"`` is the quick inner loop, plain ``pytest`` runs everything.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest

from localization.gaussian import Gaussian

#: Relative tolerance of two beliefs computed by different code paths (compiled / numpy).
BELIEF_RTOL = 1e-12


def _random_belief(
    rng: np.random.Generator, n: int, runs: int, angles: tuple[int, ...]
) -> Gaussian:
    """Beliefs over ``runs`` runs in dimension ``n`` (``n >= 4``): moving (component 3, a
    speed, in [0.5, 10]), turning both ways with every third run nearly straight (the last
    component near 0: the models' series branches), headings within 0.05 rad of +-pi, random
    well-conditioned covariances whose heading sigma points cross +-pi."""
    mean = rng.normal(size=(runs, n))
    mean[:, 3] = rng.uniform(0.5, 10.0, runs)  # a speed (CV: vx) well away from 0
    mean[::3, -1] *= 1e-9  # omega, c or vy near 0: the series branches
    for a in angles:
        mean[:, a] = np.where(rng.random(runs) < 0.5, math.pi, -math.pi) - rng.uniform(
            -0.05, 0.05, runs
        )
    root = rng.normal(size=(runs, n, n)) * 0.2
    cov = root @ root.mT + 0.05 * np.eye(n)
    if angles:
        cov[:, angles[0], angles[0]] += 0.5  # heading sigma points cross +-pi
    return Gaussian(mean, cov, angles)


def _assert_close(
    ours: Gaussian, reference: Gaussian, atol: float = 0.0, rtol: float = BELIEF_RTOL
) -> None:
    """Means equal to ``atol + rtol * (max |mean| + 1)`` (angle residuals wrapped: +pi and -pi
    are the same heading), covariances to ``atol + rtol * max |cov|``."""
    residual = reference.residual(ours.mean)
    scale = np.abs(reference.mean).max() + 1.0
    np.testing.assert_allclose(residual, 0.0, atol=atol + rtol * scale)
    np.testing.assert_allclose(
        ours.cov, reference.cov, atol=atol + rtol * np.abs(reference.cov).max(), rtol=0
    )


@pytest.fixture(scope="session")
def random_belief() -> Callable[[np.random.Generator, int, int, tuple[int, ...]], Gaussian]:
    """``random_belief(rng, n, runs, angles) -> Gaussian``: a random batch of beliefs that
    exercises the motion models' branches and the +-pi cut (see :func:`_random_belief`)."""
    return _random_belief


@pytest.fixture(scope="session")
def assert_close() -> Callable[..., None]:
    """``assert_close(ours, reference, atol=0.0, rtol=BELIEF_RTOL)``: two beliefs agree to
    rounding (see :func:`_assert_close`)."""
    return _assert_close
