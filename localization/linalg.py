"""Small numerical safeguards shared by the filters: wrapping, symmetrising, Cholesky with a policy.

Everything works on a leading batch axis: vectors ``(..., n)``, matrices ``(..., n, n)``.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy.linalg import lapack

from localization.errors import EstimationError, NumericalError

TWO_PI = 2.0 * math.pi
INV_TWO_PI = 1.0 / TWO_PI


class EstimationWarning(UserWarning):
    """Base class of the warnings the estimators emit (a safeguard acted, a target not met)."""


class CovarianceRepairWarning(EstimationWarning):
    """A covariance that was not positive definite was repaired by adding a diagonal jitter."""


class ConvergenceWarning(EstimationWarning):
    """An iterated update stopped at its iteration cap before meeting its tolerance."""


def wrap_angle(angle_rad: np.ndarray) -> np.ndarray:
    """Angles wrapped to ``[-pi, pi)`` (any shape; a float gives a numpy float).

    ``(a + pi) % 2 pi`` can round up to exactly ``2 pi`` for ``a`` just below ``-pi``; that
    result (``+pi``) is moved to ``-pi`` so the half-open range holds at the edge too.
    """
    wrapped = np.add(
        angle_rad, math.pi
    )  # a new array (or numpy float): the steps below work in place
    wrapped %= TWO_PI
    wrapped -= math.pi
    # rare: one comparison pass in the common case (not '>= pi': a NaN makes the max NaN)
    if wrapped.size and not wrapped.max() < math.pi:
        wrapped = np.where(wrapped >= math.pi, wrapped - TWO_PI, wrapped)[()]
    return wrapped


def wrap_residual(angle_rad: np.ndarray) -> np.ndarray:
    """Angle differences wrapped to ``[-pi, pi]`` (cheaper than :func:`wrap_angle`; for residuals)."""
    return angle_rad - TWO_PI * np.rint(angle_rad * INV_TWO_PI)


def wrap_columns(values: np.ndarray, angle_indices: tuple[int, ...]) -> np.ndarray:
    """``values (..., n)`` with the columns ``angle_indices`` wrapped to ``[-pi, pi)``, in place.

    Returns ``values`` for chaining; a no-op when ``angle_indices`` is empty. One vector ``(n,)``
    is wrapped with Python floats (the same formula as :func:`wrap_angle`, a tenth of the cost
    of numpy calls on scalars).
    """
    if values.ndim == 1:
        for i in angle_indices:
            wrapped = (float(values[i]) + math.pi) % TWO_PI - math.pi
            values[i] = wrapped - TWO_PI if wrapped >= math.pi else wrapped
        return values
    for i in angle_indices:
        values[..., i] = wrap_angle(values[..., i])
    return values


def symmetrise(matrix: np.ndarray) -> np.ndarray:
    """``(M + M^T) / 2`` over the last two axes."""
    return 0.5 * (matrix + matrix.mT)


def require_finite(value: np.ndarray | float, what: str, step: str) -> None:
    """Raise :class:`EstimationError` naming ``step`` and ``what`` if ``value`` holds NaN or inf.

    One reduction (the sum is NaN or inf iff an entry is, barring an overflow of entries
    near 1e308, which is refused as well); a short vector is summed by Python, a fifth of the
    cost of a numpy reduction.
    """
    if isinstance(value, np.ndarray) and value.ndim == 1 and value.size <= 64:
        total = sum(value.tolist())
    else:
        total = np.add.reduce(value, axis=None)
    if not math.isfinite(total):
        raise EstimationError(f"{step}: {what} is not finite (NaN, inf or overflow)")


@dataclass(frozen=True)
class PDPolicy:
    """What a filter does when a covariance it must factorise is not positive definite.

    Attributes:
        action: ``"raise"`` (default) raises :class:`EstimationError` naming the step;
            ``"repair"`` adds ``jitter * I`` to the failing covariances, with ``jitter`` the
            smallest value ``max(-lambda_min, 0) + relative_jitter * max(trace / n, tiny)``
            that makes them positive definite, and emits a :class:`CovarianceRepairWarning`
            that reports the largest jitter used.
        relative_jitter: the margin of a repair, relative to the mean variance (trace / n).
    """

    action: Literal["raise", "repair"] = "raise"
    relative_jitter: float = 1e-9

    def __post_init__(self) -> None:
        if self.action not in ("raise", "repair"):
            raise EstimationError(
                f"PDPolicy: action must be 'raise' or 'repair', got {self.action!r}"
            )
        if not (math.isfinite(self.relative_jitter) and self.relative_jitter > 0.0):
            raise EstimationError(
                f"PDPolicy: relative_jitter must be finite and > 0, got {self.relative_jitter!r}"
            )


def cholesky(cov: np.ndarray, policy: PDPolicy, step: str) -> tuple[np.ndarray, np.ndarray]:
    """Lower Cholesky factor of ``cov (..., n, n)``, applying ``policy`` if it is not PD.

    Returns ``(factor, used)``: ``used`` is ``cov`` itself, or the repaired covariance
    ``factor @ factor^T`` was taken from (so a filter goes on with the matrix it factorised).

    One matrix ``(n, n)`` goes to LAPACK's ``potrf`` directly (about 1 us against 5-8 us for
    ``np.linalg.cholesky``, whose cost on a 5x5 matrix is its Python wrapper); it computes the
    same factor, bit for bit, as ``np.linalg.cholesky`` does for each matrix of a batch.

    Raises:
        EstimationError: ``cov`` is not finite, or not positive definite under ``"raise"``.
    """
    if cov.ndim == 2:
        factor, info = lapack.dpotrf(cov, lower=1)  # lower triangle read, upper zeroed
        if info == 0:  # C order, as from np.linalg.cholesky: later products then round alike
            return np.ascontiguousarray(factor), cov
    else:
        try:
            return np.linalg.cholesky(cov), cov
        except np.linalg.LinAlgError:
            pass
    require_finite(cov, "the covariance", step)
    eigenvalues = np.linalg.eigvalsh(symmetrise(cov))  # (..., n), ascending
    smallest = eigenvalues[..., 0]
    if policy.action == "raise":
        raise EstimationError(
            f"{step}: the covariance is not positive definite "
            f"(smallest eigenvalue {float(np.min(smallest)):.3g}); PDPolicy action is 'raise'"
        )
    n = cov.shape[-1]
    scale = np.maximum(np.trace(cov, axis1=-2, axis2=-1) / n, np.finfo(float).tiny)
    jitter = np.where(
        smallest > policy.relative_jitter * scale,
        0.0,
        np.maximum(-smallest, 0.0) + policy.relative_jitter * scale,
    )
    repaired = symmetrise(cov) + jitter[..., None, None] * np.eye(n)
    warnings.warn(
        CovarianceRepairWarning(
            f"{step}: covariance not positive definite, repaired with a diagonal jitter of "
            f"{float(np.max(jitter)):.3g} (largest over the batch)"
        ),
        stacklevel=3,
    )
    try:
        return np.linalg.cholesky(repaired), repaired
    except np.linalg.LinAlgError as exc:
        raise EstimationError(f"{step}: the covariance could not be repaired ({exc})") from exc


def solve(matrix: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """``matrix^-1 rhs`` for ``matrix (..., m, m)`` and ``rhs (..., m, k)`` by LU, never inverted.

    One system goes to LAPACK's ``gesv`` directly (1.5 us against 6 us for the wrapper of
    ``np.linalg.solve`` on 3x3); a batch to ``np.linalg.solve``, which runs the same ``gesv``
    on each system, so the two agree to the last bit.

    Raises:
        NumericalError: a system is singular (to working precision).
    """
    if matrix.ndim == 2 and rhs.ndim == 2:
        _, _, solution, info = lapack.dgesv(matrix, rhs)
        if info == 0:  # C order, as from np.linalg.solve: later products then round alike
            return np.ascontiguousarray(solution)
    try:
        return np.linalg.solve(matrix, rhs)
    except np.linalg.LinAlgError as exc:
        raise NumericalError(
            f"solve: the {matrix.shape[-1]}x{matrix.shape[-1]} system is singular ({exc})"
        ) from None
