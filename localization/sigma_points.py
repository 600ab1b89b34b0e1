"""Sigma points of the unscented transform and the weighted moments of transformed points.

Three parametrisations, all of the form (``n`` the dimension, ``L`` the lower Cholesky
factor of the covariance, ``L_i`` its ``i``-th column)::

    X_0 = m,   X_i = m + gamma L_i,   X_{n+i} = m - gamma L_i           (i = 1..n)
    Wm_0 = 1 - n / gamma^2,   Wm_i = Wc_i = 1 / (2 gamma^2),   Wc_0 = Wm_0 + c0

- :class:`ScaledSigmaPoints` (Wan and van der Merwe; paper 001 eq. 25, 28):
  ``gamma^2 = alpha^2 (n + kappa)``, ``c0 = 1 - alpha^2 + beta``.
- :class:`KappaSigmaPoints` (Julier; paper 000 eq. 1): ``gamma^2 = n + kappa``, ``c0 = 0``.
- :class:`SpreadSigmaPoints` (paper 004 eq. 3, 7): ``gamma = a sqrt(n)``, ``c0 = 0``.

Moments about the centre point. A small ``alpha`` (paper 001 uses ``alpha = 1e-5``, so
``gamma^2 = 3e-10`` and ``Wm_0 = -1.7e10`` for a 5-state model) puts weights of size ``1e10``
of both signs into the textbook sums. :func:`unscented_moments` never multiplies by ``Wm_0``.
With ``D_i = Y_i - Y_0`` (angles wrapped) and ``d = sum_{i>=1} Wm_i D_i`` it uses the exact
identities (they follow from ``sum_i Wm_i = 1``)::

    y = Y_0 + d
    sum_i Wc_i (Y_i - y)(Y_i - y)^T = sum_{i>=1} Wc_i D_i D_i^T + (c0 - 1) d d^T

The first term is positive semi-definite whatever the sign of ``Wm_0``; with ``c0 >= 1``
(scaled points with ``beta >= alpha^2``, e.g. ``beta = 2``) the covariance is PSD by
construction, and angle residuals are wrapped offsets about the centre image. With ``c0 = 0``
(papers 000 and 004) and a negative ``Wm_0`` it can lose definiteness: the filters'
:class:`~localization.linalg.PDPolicy` then decides. What no formula removes: with tiny
``alpha`` the second-order mean term ``d`` is a finite difference with a step of ``gamma``
standard deviations, so it carries a rounding error of about ``eps |y| / gamma^2`` (``1e-4``
for ``|y| = 300`` at ``alpha = 1e-5``); ``alpha >= 1e-3`` avoids it.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from typing import TypeVar

import numpy as np

from localization.errors import EstimationError
from localization.linalg import wrap_columns, wrap_residual


@dataclass(frozen=True)
class SigmaWeights:
    """The weights of ``2n + 1`` sigma points in dimension ``n`` (see the module docstring).

    Attributes:
        n: dimension.
        gamma: multiplier of the Cholesky columns.
        wm0: mean weight of the centre point (may be hugely negative; never used in sums).
        wi: mean and covariance weight of each of the other ``2n`` points.
        c0: ``Wc_0 - Wm_0``.
        deviation_weights: ``(2n,)`` all equal to ``wi`` (a vector for one-call weighted sums).
        offsets: ``(2n + 1, n)`` rows ``0, gamma e_i, -gamma e_i`` (``offsets @ L^T`` are the
            displacements of the sigma points from the mean).
    """

    n: int
    gamma: float
    wm0: float
    wi: float
    c0: float
    deviation_weights: np.ndarray
    offsets: np.ndarray

    @cached_property
    def half_moment_weights(self) -> np.ndarray:
        """``(2n + 1,)`` ``Wi / 2`` (``2n`` times), then ``(c0 - 1) / 2``: the weights of the rows of
        ``[D; d]`` in half the covariance (see :func:`unscented_moments`). Cached, read-only."""
        weights = np.full(2 * self.n + 1, 0.5 * self.wi)
        weights[-1] = 0.5 * (self.c0 - 1.0)
        weights.flags.writeable = False
        return weights

    @cached_property
    def packed(self) -> np.ndarray:
        """``(3,)`` ``(gamma, Wi, c0)``, read-only: the weights as the compiled UKF takes them
        (:mod:`localization.compiled.ukf`). Cached with the weights, so a step builds nothing."""
        packed = np.array([self.gamma, self.wi, self.c0])
        packed.flags.writeable = False
        return packed

    @property
    def mean_weights(self) -> np.ndarray:
        """``(2n + 1,)`` weights of the mean (for reference and tests)."""
        return np.concatenate([[self.wm0], np.full(2 * self.n, self.wi)])

    @property
    def cov_weights(self) -> np.ndarray:
        """``(2n + 1,)`` weights of the covariance (for reference and tests)."""
        return np.concatenate([[self.wm0 + self.c0], np.full(2 * self.n, self.wi)])


def _weights(n: int, gamma2: float, c0: float) -> SigmaWeights:
    gamma = math.sqrt(gamma2)
    deviation_weights = np.full(2 * n, 0.5 / gamma2)
    offsets = gamma * np.concatenate([np.zeros((1, n)), np.eye(n), -np.eye(n)])
    deviation_weights.flags.writeable = False
    offsets.flags.writeable = False
    return SigmaWeights(
        n=n,
        gamma=gamma,
        wm0=1.0 - n / gamma2,
        wi=0.5 / gamma2,
        c0=c0,
        deviation_weights=deviation_weights,
        offsets=offsets,
    )


def _check_dimension(owner: str, n: int) -> None:
    if not (isinstance(n, (int, np.integer)) and n >= 1):
        raise EstimationError(f"{owner}: dimension must be an integer >= 1, got {n!r}")


def _resolved_kappa(owner: str, n: int, kappa: float | None) -> float:
    """``kappa`` (``3 - n`` when ``None``) after checking ``n >= 1`` and ``n + kappa > 0``."""
    _check_dimension(owner, n)
    kappa = 3.0 - n if kappa is None else kappa
    if n + kappa <= 0.0:
        raise EstimationError(f"{owner}: n + kappa must be > 0, got n={n}, kappa={kappa}")
    return kappa


_SchemeT = TypeVar("_SchemeT")  # a sigma-point settings class


def _per_dimension(
    build: Callable[[_SchemeT, int], SigmaWeights],
) -> Callable[[_SchemeT, int], SigmaWeights]:
    """``weights(self, n)`` cached in the instance's ``__dict__`` (a frozen dataclass allows that).

    A dictionary lookup per step: ``functools.lru_cache`` would hash the settings dataclass on
    every call, a microsecond of a filter step.
    """

    @functools.wraps(build)
    def weights(self: _SchemeT, n: int) -> SigmaWeights:
        cache = self.__dict__.setdefault("_weights_by_dimension", {})
        found = cache.get(n)
        if found is None:
            found = cache[n] = build(self, n)
        return found

    return weights


@dataclass(frozen=True)
class ScaledSigmaPoints:
    """Scaled sigma points (Wan and van der Merwe): ``gamma^2 = alpha^2 (n + kappa)``.

    Attributes:
        alpha: spread, ``> 0`` (paper 001: ``1e-5``).
        beta: prior-knowledge weight, 2 for Gaussians.
        kappa: secondary scaling; ``n + kappa > 0`` is checked when the weights are built.
            ``None`` means ``3 - n`` (paper 001).
    """

    alpha: float = 1e-3
    beta: float = 2.0
    kappa: float | None = 0.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.alpha) and self.alpha > 0.0):
            raise EstimationError(
                f"ScaledSigmaPoints: alpha must be finite and > 0, got {self.alpha!r}"
            )
        if not math.isfinite(self.beta):
            raise EstimationError(f"ScaledSigmaPoints: beta must be finite, got {self.beta!r}")
        if self.kappa is not None and not math.isfinite(self.kappa):
            raise EstimationError(
                f"ScaledSigmaPoints: kappa must be finite or None, got {self.kappa!r}"
            )

    @_per_dimension
    def weights(self, n: int) -> SigmaWeights:
        """The weights in dimension ``n`` (cached)."""
        kappa = _resolved_kappa("ScaledSigmaPoints", n, self.kappa)
        return _weights(int(n), self.alpha**2 * (n + kappa), 1.0 - self.alpha**2 + self.beta)


@dataclass(frozen=True)
class KappaSigmaPoints:
    """Julier's sigma points (paper 000 eq. 1): ``gamma^2 = n + kappa``, ``W_0 = kappa / (n + kappa)``.

    Attributes:
        kappa: ``n + kappa > 0`` is checked when the weights are built; ``None`` means
            ``3 - n`` (Julier's choice matching the fourth moment of a Gaussian).
    """

    kappa: float | None = None

    def __post_init__(self) -> None:
        if self.kappa is not None and not math.isfinite(self.kappa):
            raise EstimationError(
                f"KappaSigmaPoints: kappa must be finite or None, got {self.kappa!r}"
            )

    @_per_dimension
    def weights(self, n: int) -> SigmaWeights:
        """The weights in dimension ``n`` (cached)."""
        kappa = _resolved_kappa("KappaSigmaPoints", n, self.kappa)
        return _weights(int(n), float(n + kappa), 0.0)


@dataclass(frozen=True)
class SpreadSigmaPoints:
    """Paper 004's sigma points (eq. 3, 7): ``X_i = m +- a (sqrt(n P))_i``, ``W_0 = 1 - 1/a^2``.

    Attributes:
        a: spread, ``> 0`` (paper 004: ``0.1``).
    """

    a: float = 0.1

    def __post_init__(self) -> None:
        if not (math.isfinite(self.a) and self.a > 0.0):
            raise EstimationError(f"SpreadSigmaPoints: a must be finite and > 0, got {self.a!r}")

    @_per_dimension
    def weights(self, n: int) -> SigmaWeights:
        """The weights in dimension ``n`` (cached)."""
        _check_dimension("SpreadSigmaPoints", n)
        return _weights(int(n), self.a**2 * n, 0.0)


SigmaPointScheme = ScaledSigmaPoints | KappaSigmaPoints | SpreadSigmaPoints


def sigma_points(mean: np.ndarray, chol: np.ndarray, weights: SigmaWeights) -> np.ndarray:
    """The ``(..., 2n + 1, n)`` sigma points of ``mean (..., n)`` with Cholesky factor ``chol (..., n, n)``.

    Point 0 is the mean, points ``1..n`` add ``gamma`` times the columns of ``chol``, points
    ``n+1..2n`` subtract them. Angles are not wrapped here (models are periodic in them).
    """
    if mean.ndim == 1:  # one run: a single matmul is the cheapest
        return mean + weights.offsets @ chol.mT
    n = weights.n
    spread = weights.gamma * chol.mT  # row i = gamma L_i
    points = np.empty(mean.shape[:-1] + (2 * n + 1, n))
    points[..., 0, :] = mean
    centre = mean[..., None, :]
    np.add(centre, spread, out=points[..., 1 : n + 1, :])
    np.subtract(centre, spread, out=points[..., n + 1 :, :])
    return points


def unscented_moments(
    points: np.ndarray, weights: SigmaWeights, angle_indices: tuple[int, ...] = ()
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Weighted mean and covariance of transformed sigma points, taken about the centre point.

    Args:
        points: ``(..., 2n + 1, m)`` transformed sigma points, point 0 the image of the mean.
        weights: the weights the points were drawn with.
        angle_indices: components of the points that are angles (wrapped offsets).

    Returns:
        ``mean (..., m)`` (angles wrapped to ``[-pi, pi)``), ``cov (..., m, m)`` (exactly
        symmetric) and the deviations ``D (..., 2n, m)`` of points ``1..2n`` from point 0
        (they feed :func:`cross_covariance`).

    The deviations and ``d`` are stacked as ``E = [D; d]`` ``(..., 2n + 1, m)``, so that the
    covariance is one product ``E^T diag(Wi, .., Wi, c0 - 1) E`` (taken as half of it plus its
    transpose, which makes it exactly symmetric). A few numpy calls, the same for one run and
    for a batch: a batch gives the numbers of its runs one by one to the last bit (which
    matters: with a small ``alpha`` the mean shift amplifies any rounding difference by
    ``1 / gamma^2``). An angle wrap is skipped when every angle deviation is below 3 rad in
    magnitude: it would return them unchanged (``rint(d / 2 pi) = 0``), and the check costs
    half of it.
    """
    k = points.shape[-2] - 1  # 2n
    stacked = np.empty(points.shape[:-2] + (k + 1, points.shape[-1]))  # E = [D; d]
    dev = stacked[..., :k, :]
    np.subtract(points[..., 1:, :], points[..., :1, :], out=dev)
    for i in angle_indices:
        column = dev[..., i]
        # the largest |D| (one run: by Python, a third of the cost); a NaN may take either branch
        largest = (
            max(map(abs, column.tolist())) if column.ndim == 1 else np.abs(column).max(initial=0.0)
        )
        if not largest < 3.0:
            dev[..., i] = wrap_residual(column)
    shift = stacked[..., k, :]
    np.matmul(weights.deviation_weights, dev, out=shift)  # d = sum_{i>=1} W_i D_i
    half = (weights.half_moment_weights[:, None] * stacked).mT @ stacked
    cov = half + half.mT  # Wi D^T D + (c0 - 1) d d^T
    mean = points[..., 0, :] + shift
    if angle_indices:
        wrap_columns(mean, angle_indices)
    return mean, cov, dev


def cross_covariance(chol: np.ndarray, dev_z: np.ndarray, weights: SigmaWeights) -> np.ndarray:
    """``Pxz = sum_i Wc_i (X_i - x)(Z_i - z)^T`` ``(..., n, m)`` for points drawn by :func:`sigma_points`.

    ``chol (..., n, n)`` is the factor the points were drawn with and ``dev_z (..., 2n, m)`` the
    deviations returned by :func:`unscented_moments`. As ``X_i - x = +-gamma L_i`` and these
    displacements sum to zero, ``Pxz = Wi gamma L (D_{1..n} - D_{n+1..2n})`` exactly.
    """
    n = weights.n
    return (weights.wi * weights.gamma) * (chol @ (dev_z[..., :n, :] - dev_z[..., n:, :]))
