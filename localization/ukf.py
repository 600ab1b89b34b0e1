"""The unscented Kalman filter, additive or augmented process noise (papers 000, 001, 004).

Pure steps on immutable :class:`~localization.gaussian.Gaussian` beliefs, one run ``(n,)`` or a
batch ``(B, n)`` in one call::

    ukf = UnscentedKalmanFilter(points=ScaledSigmaPoints(alpha=1e-3))
    belief = ukf.predict(belief, process_model, u, dt_s)
    belief = ukf.update(belief, z, measurement_model)

Prediction (paper 001 eq. 25-27; paper 000 eq. 3-5; paper 004 eq. 3-6)::

    X = sigma points of (x, P)             [of (x, 0; P, 0; 0, Q) if augmented]
    Y_i = f(X_i, *args)                    [f(X_i^x, X_i^w, *args) if augmented]
    x- = sum Wm_i Y_i,  P- = sum Wc_i (Y_i - x-)(Y_i - x-)^T  (+ Q if additive)

Update (paper 001 eq. 29-35, paper 004 eq. 8-14; new sigma points are drawn from the predicted
belief, as in paper 004 eq. 8)::

    Z_i = h(X_i),  z- = sum Wm_i Z_i,  S = sum Wc_i (Z_i - z-)(Z_i - z-)^T + R
    Pxz = sum Wc_i (X_i - x-)(Z_i - z-)^T,  K = Pxz S^-1   (solved, never inverted)
    x+ = x- + K (z - z-),  P+ = P- - K S K^T = P- - Pxz K^T   (symmetrised)

(Paper 001 eq. 35 prints ``+ K U K^T``; the minus sign is the correct one.) The weighted sums
are taken about the centre sigma point (see :mod:`localization.sigma_points`), which keeps
paper 001's ``alpha = 1e-5`` exact. Angles declared in the belief and in the measurement
model are wrapped in every residual and mean.

Two paths. When a model carries a per-point kernel (``point=``, e.g. the models built by
``CTRV.process_model(Q)``, :func:`~localization.motion_models.pose_model`) and the step can be
expressed there (a flat batch or one run, arguments that are numbers), the step runs compiled
(:mod:`localization.compiled.ukf`: one call per step, the same maths term by term, equal to
rounding; about 20 us for a CTRV predict + update instead of about 100 us). Otherwise, and
whenever the compiled step declines (a covariance not positive definite, a non-finite input
or result), the numpy path below takes the step; it is the reference, and the one that
applies the :class:`~localization.linalg.PDPolicy` and raises the errors.

Speed of the numpy path (``benchmarks/ukf_step.py``). A step is a few dozen numpy calls whatever the batch
size, so one run pays mostly call overheads: its Cholesky factor and solve go to LAPACK
directly, the moments are a handful of products (:func:`~localization.sigma_points.unscented_moments`),
and the checks are cheap finiteness tests of the inputs and the new mean. One run and a batch take the same
floating-point operations, so a batch gives its runs' numbers to the last bit (with a small
``alpha`` the mean shift would amplify any rounding difference by ``1 / gamma^2``). Long
batches are stepped in slices of :data:`SLICE_RUNS` runs.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np

from localization.compiled import ukf as compiled_ukf
from localization.errors import EstimationError
from localization.gaussian import Gaussian
from localization.linalg import PDPolicy, cholesky, require_finite, solve, wrap_columns
from localization.models import MeasurementModel, ProcessModel, ProcessNoise
from localization.sigma_points import (
    ScaledSigmaPoints,
    SigmaPointScheme,
    cross_covariance,
    sigma_points,
    unscented_moments,
)


def at_sigma_points(args: tuple, batch_shape: tuple[int, ...]) -> tuple:
    """The step's arguments, per-run arrays given a sigma-point axis after the batch axes.

    An array whose leading axes equal ``batch_shape`` (non-empty) is per-run: ``(B,)`` becomes
    ``(B, 1)`` and ``(B, k)`` becomes ``(B, 1, k)``, so it broadcasts against the sigma points
    ``(B, 2n + 1, n)``. Everything else (floats, shared arrays) passes unchanged.
    """
    if not batch_shape:
        return args
    d = len(batch_shape)
    return tuple(
        np.expand_dims(a, d) if isinstance(a, np.ndarray) and a.shape[:d] == batch_shape else a
        for a in args
    )


def check_args(args: tuple, step: str) -> None:
    """Refuse non-finite step inputs (controls, time steps) with an :class:`EstimationError`."""
    for position, value in enumerate(args):
        if isinstance(value, float):
            if not math.isfinite(value):
                raise EstimationError(f"{step}: argument {position + 1} is not finite (NaN or inf)")
        elif isinstance(value, np.ndarray):
            require_finite(value, f"argument {position + 1}", step)


def kalman_correction(
    mean: np.ndarray,
    cov: np.ndarray,
    innovation: np.ndarray,
    cross_cov: np.ndarray,
    innovation_cov: np.ndarray,
    angle_indices: tuple[int, ...],
) -> tuple[np.ndarray, np.ndarray]:
    """``x + K y`` and ``P - Pxz K^T`` (symmetrised) with ``K = Pxz S^-1`` solved (shared by UKF variants).

    Shapes: ``mean (..., n)``, ``cov (..., n, n)``, ``innovation (..., m)``, ``cross_cov (..., n, m)``,
    ``innovation_cov (..., m, m)``. The same LU solve for one run and for a batch (see
    :func:`~localization.linalg.solve`).
    """
    gain_t = solve(innovation_cov, cross_cov.mT)  # K^T = S^-1 Pxz^T
    new_mean = mean + (innovation[..., None, :] @ gain_t)[..., 0, :]
    new_cov = cov - cross_cov @ gain_t
    new_cov += new_cov.mT  # symmetrised in place: (P + P^T) / 2
    new_cov *= 0.5
    return wrap_columns(new_mean, angle_indices), new_cov


#: Batches of more runs than this are stepped in slices of at most this many runs. Every
#: operation is per run, so the numbers are the same bit for bit; the slices keep each
#: temporary array (``(runs, 2n + 1, n)`` sigma points and images) small enough to stay in the
#: CPU cache and on the malloc heap. A 1000-run CTRV step in one piece spends about a fifth
#: of its time in page faults: glibc returns such arrays to the system after every step and
#: faults them in again (measured in ``benchmarks/ukf_step.py``).
SLICE_RUNS = 512


def run_slices(batch_shape: tuple[int, ...], noise_cov: np.ndarray) -> list[slice] | None:
    """Near-equal slices of at most :data:`SLICE_RUNS` runs, or ``None`` (step in one piece).

    Only a flat batch ``(B,)`` longer than :data:`SLICE_RUNS` with a shared noise covariance
    ``(k, k)`` is sliced.
    """
    if len(batch_shape) != 1 or batch_shape[0] <= SLICE_RUNS or noise_cov.ndim != 2:
        return None
    runs = batch_shape[0]
    count = -(-runs // SLICE_RUNS)
    edges = [runs * i // count for i in range(count + 1)]
    return [slice(start, stop) for start, stop in itertools.pairwise(edges)]


def sliced_args(args: tuple, runs: int, part: slice) -> tuple:
    """The step's arguments for the runs ``part``: per-run arrays (leading axis ``runs``) sliced."""
    return tuple(
        a[part] if isinstance(a, np.ndarray) and a.shape[:1] == (runs,) else a for a in args
    )


def joined(beliefs: list[Gaussian], angle_indices: tuple[int, ...]) -> Gaussian:
    """One belief from the beliefs of consecutive slices of a batch."""
    mean = np.concatenate([b.mean for b in beliefs])
    cov = np.concatenate([b.cov for b in beliefs])
    return Gaussian.trusted(mean, cov, angle_indices)


@dataclass(frozen=True)
class UnscentedKalmanFilter:
    """UKF settings; ``predict`` and ``update`` are pure steps.

    Attributes:
        points: the sigma-point parametrisation (scaled, kappa or spread; see
            :mod:`localization.sigma_points`).
        pd_policy: what to do when a covariance to factorise is not positive definite.
    """

    points: SigmaPointScheme = field(default_factory=ScaledSigmaPoints)
    pd_policy: PDPolicy = field(default_factory=PDPolicy)

    def predict(self, belief: Gaussian, model: ProcessModel, *args) -> Gaussian:
        """The belief propagated one step through ``model`` (additive or augmented noise).

        Raises:
            EstimationError: non-finite ``args`` or result, or a covariance that is not
                positive definite under the ``"raise"`` policy.
        """
        mean = belief.mean
        n = mean.shape[-1]
        if model.point is not None:
            dim = n + model.Q.shape[-1] if model.noise == ProcessNoise.AUGMENTED else n
            done = compiled_ukf.predict(
                self.points.weights(dim), mean, belief.cov, belief.angle_indices, model, args
            )
            if done is not None:
                return Gaussian.trusted(*done, belief.angle_indices)
        batch = mean.shape[:-1]
        if len(batch) == 1 and batch[0] > SLICE_RUNS and (parts := run_slices(batch, model.Q)):
            steps = [
                self.predict(belief[part], model, *sliced_args(args, batch[0], part))
                for part in parts
            ]
            return joined(steps, belief.angle_indices)
        check_args(args, "UKF predict")
        chol, _ = cholesky(belief.cov, self.pd_policy, "UKF predict")
        if model.noise == ProcessNoise.ADDITIVE:
            weights = self.points.weights(n)
            images = model.f(sigma_points(mean, chol, weights), *at_sigma_points(args, batch))
        else:
            q = model.Q.shape[-1]
            weights = self.points.weights(n + q)
            mean_aug = np.zeros(batch + (n + q,))
            mean_aug[..., :n] = mean
            chol_aug = np.zeros(batch + (n + q, n + q))  # a square root of blockdiag(P, Q)
            chol_aug[..., :n, :n] = chol
            chol_aug[..., n:, n:] = model.noise_sqrt
            points = sigma_points(mean_aug, chol_aug, weights)
            images = model.f(points[..., :n], points[..., n:], *at_sigma_points(args, batch))
        angles = belief.angle_indices
        mean, cov, _ = unscented_moments(images, weights, angles)
        if model.noise == ProcessNoise.ADDITIVE:
            cov = cov + model.Q  # paper 004 eq. 6 (both exactly symmetric)
        require_finite(mean, "the predicted mean (model output)", "UKF predict")
        return Gaussian.trusted(mean, cov, angles)

    def update(self, belief: Gaussian, z: np.ndarray, model: MeasurementModel, *args) -> Gaussian:
        """The belief corrected by the measurement ``z (..., m)``.

        Raises:
            EstimationError: non-finite ``z``, ``args`` or result, or a covariance that is not
                positive definite under the ``"raise"`` policy.
        """
        mean = belief.mean
        if model.point is not None:
            done = compiled_ukf.update(
                self.points.weights(mean.shape[-1]),
                mean,
                belief.cov,
                belief.angle_indices,
                z,
                model,
                args,
            )
            if done is not None:
                return Gaussian.trusted(*done, belief.angle_indices)
        batch = mean.shape[:-1]
        if (
            len(batch) == 1
            and batch[0] > SLICE_RUNS
            and (parts := run_slices(batch, model.R))
            and isinstance(z, np.ndarray)
            and z.shape == batch + model.R.shape[-1:]  # else refused whole
        ):
            steps = [
                self.update(belief[part], z[part], model, *sliced_args(args, batch[0], part))
                for part in parts
            ]
            return joined(steps, belief.angle_indices)
        require_finite(z, "the measurement z", "UKF update")
        check_args(args, "UKF update")
        weights = self.points.weights(mean.shape[-1])
        chol, prior_cov = cholesky(belief.cov, self.pd_policy, "UKF update")
        images = model.h(sigma_points(mean, chol, weights), *at_sigma_points(args, mean.shape[:-1]))
        z_pred, s_cov, dev = unscented_moments(images, weights, model.angle_indices)
        s_cov = s_cov + model.R
        mean, cov = kalman_correction(
            mean,
            prior_cov,
            model.residual(z, z_pred, "UKF update"),
            cross_covariance(chol, dev, weights),
            s_cov,
            belief.angle_indices,
        )
        require_finite(mean, "the updated mean", "UKF update")
        return Gaussian.trusted(mean, cov, belief.angle_indices)
