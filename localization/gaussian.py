"""The Gaussian belief every filter step takes and returns."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from localization.errors import EstimationError
from localization.linalg import symmetrise, wrap_columns


@dataclass(frozen=True)
class Gaussian:
    """A Gaussian belief over a state, for one run or a batch of runs.

    Attributes:
        mean: ``(..., n)`` state mean; angle components wrapped to ``[-pi, pi)``.
        cov: ``(..., n, n)`` symmetric positive-definite covariance.
        angle_indices: the state components that are angles in radians. Their residuals are
            wrapped and their weighted means are taken as wrapped offsets about a reference
            point, never as raw averages.

    The constructor checks shapes and finiteness, symmetrises ``cov`` and wraps the angles;
    the arrays are copied and made read-only. Filters build their results through
    :meth:`trusted`, which skips those checks in the hot path.

    Raises:
        EstimationError: shapes that do not match, non-finite values, bad angle indices.
    """

    mean: np.ndarray
    cov: np.ndarray
    angle_indices: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        mean = np.array(self.mean, dtype=float)
        cov = np.array(self.cov, dtype=float)
        if mean.ndim < 1:
            raise EstimationError("Gaussian: mean must have shape (..., n)")
        n = mean.shape[-1]
        if cov.shape != mean.shape + (n,):
            raise EstimationError(
                f"Gaussian: cov shape {cov.shape} does not match mean shape {mean.shape} "
                f"(expected {mean.shape + (n,)})"
            )
        if not (np.isfinite(mean).all() and np.isfinite(cov).all()):
            raise EstimationError("Gaussian: mean or cov is not finite (NaN or inf)")
        angles = tuple(int(i) for i in self.angle_indices)
        if any(i < 0 or i >= n for i in angles) or len(set(angles)) != len(angles):
            raise EstimationError(
                f"Gaussian: angle_indices {self.angle_indices!r} must be distinct indices in [0, {n})"
            )
        wrap_columns(mean, angles)
        cov = symmetrise(cov)
        mean.flags.writeable = False
        cov.flags.writeable = False
        object.__setattr__(self, "mean", mean)
        object.__setattr__(self, "cov", cov)
        object.__setattr__(self, "angle_indices", angles)

    @classmethod
    def trusted(cls, mean: np.ndarray, cov: np.ndarray, angle_indices: tuple[int, ...]) -> Gaussian:
        """A belief from arrays a filter has just computed: no copy, no checks (hot path).

        The arrays are made read-only, so a belief stays immutable whoever made it.
        """
        mean.setflags(write=False)
        cov.setflags(write=False)
        belief = object.__new__(cls)
        belief.__dict__.update(
            mean=mean, cov=cov, angle_indices=angle_indices
        )  # frozen: bypass __setattr__
        return belief

    @property
    def dim(self) -> int:
        """The state dimension ``n``."""
        return self.mean.shape[-1]

    @property
    def batch_shape(self) -> tuple[int, ...]:
        """The leading batch shape: ``()`` for one run, ``(B,)`` for ``B`` runs."""
        return self.mean.shape[:-1]

    @property
    def std(self) -> np.ndarray:
        """``(..., n)`` standard deviations (square roots of the variances)."""
        return np.sqrt(np.diagonal(self.cov, axis1=-2, axis2=-1))

    def residual(self, state: np.ndarray) -> np.ndarray:
        """``state - mean`` over ``(..., n)``, angle components wrapped to ``[-pi, pi)``."""
        return wrap_columns(np.asarray(state, dtype=float) - self.mean, self.angle_indices)

    def __getitem__(self, index) -> Gaussian:
        """The belief of some runs of a batch: ``belief[i]``, ``belief[2:5]``."""
        if not self.batch_shape:
            raise EstimationError("Gaussian: a single-run belief cannot be indexed")
        return Gaussian.trusted(self.mean[index], self.cov[index], self.angle_indices)
