"""One filter stepped in place: a compiled call per step, or one call for a whole sequence.

:class:`~localization.ukf.UnscentedKalmanFilter` and
:class:`~localization.ekf.ExtendedKalmanFilter` take immutable beliefs and any batch, so each
step checks its inputs, packs its arguments and builds two result beliefs around its two
compiled calls: for one CTRV filter that Python is most of a 14 us step. :class:`LeanUKF` and
:class:`LeanEKF` hold one run of a known model instead: everything about the model (the
kernels, ``Q``, ``R``, the sigma weights, the step's arguments, the angle indices) is checked
and packed once, at construction, into two arrays; a step is then one compiled call
(:func:`ukf_step`, :func:`ekf_step`) on the filter's own state and covariance arrays, which it
overwrites::

    lean = LeanUKF(UnscentedKalmanFilter(), CTRV.process_model(Q), pose_model(R), belief, dt_s)
    for z in measurements:        # z (m,) float64
        lean.step(z)              # predict + update, in place
    lean.mean, lean.cov           # read-only views of the state
    means, covs = lean.run(zs)    # zs (T, m): T steps in one call, (T, n) and (T, n, n)

The arithmetic is that of the batched steps, the same cores on one run
(:func:`localization.compiled.ukf.predict_core` and ``update_core``, the EKF's likewise), so a
lean step equals the :class:`~localization.ukf.UnscentedKalmanFilter` step on the same belief
bit for bit (tested). What the lean filters do not do: batches (a batch already pays its Python
once per step for all runs), user kernels (the built-in motion models of
:mod:`localization.motion_models` with the GPS or pose measurement), and the
:class:`~localization.linalg.PDPolicy` repairs: a covariance that is not positive definite,
or a non-finite measurement or result, raises an :class:`~localization.errors.EstimationError`
and leaves the state as it was before the failing step.

Packing (:func:`pack`). ``layout`` (int64): the process kernel's number
(:data:`localization.compiled.motion.MODEL_NUMBERS`), augmented (0/1), ``n``, ``m``, the
number ``k`` of packed step arguments, the noise dimension ``q`` (``n`` additive), the counts of
state and measurement angle indices, then those indices. ``consts`` (float64): the predict and
update sigma weights ``(gamma, W_i, c0)`` (zeros for the EKF), the step arguments ``(k,)``,
the process noise (``Q (n, n)`` additive, its square root ``S (q, q)`` augmented) and
``R (m, m)``, flattened.
"""

from __future__ import annotations

import numba
import numpy as np

from localization.compiled import ekf, motion, ukf
from localization.compiled.glue import NOT_POSITIVE_DEFINITE, OK, pack_args
from localization.errors import EstimationError
from localization.gaussian import Gaussian
from localization.models import MeasurementModel, ProcessModel, ProcessNoise

# layout entries
_MODEL, _AUGMENTED, _N, _M, _K, _Q, _STATE_ANGLES, _MEASUREMENT_ANGLES = range(8)
_HEADER = 8
#: consts entries before the step arguments: the predict and the update weights
_WEIGHTS = 6
_F64 = np.dtype(np.float64)

#: State dimension of each built-in process kernel, by its number.
STATE_DIMENSIONS = {
    motion.MODEL_NUMBERS["CV"]: 4,
    motion.MODEL_NUMBERS["CTRV"]: 5,
    motion.MODEL_NUMBERS["CTRA"]: 6,
    motion.MODEL_NUMBERS["CCA"]: 6,
}


# ------------------------------------------------------------------------ compiled entries


@numba.njit(cache=True)
def _unpack(consts, layout):
    """Views of the packed constants: ``(predict weights (3,), update weights (3,), args (1, k),
    noise (1, q, q), R (1, m, m), state angles, measurement angles)``."""
    m, k, q = layout[_M], layout[_K], layout[_Q]
    first = _HEADER + layout[_STATE_ANGLES]
    state_angles = layout[_HEADER:first]
    measurement_angles = layout[first : first + layout[_MEASUREMENT_ANGLES]]
    start = _WEIGHTS
    args = consts[start : start + k].reshape((1, k))
    start += k
    noise = consts[start : start + q * q].reshape((1, q, q))
    start += q * q
    r_cov = consts[start : start + m * m].reshape((1, m, m))
    return consts[0:3], consts[3:6], args, noise, r_cov, state_angles, measurement_angles


@numba.njit(cache=True)
def _ukf_once(mean, cov, z, consts, layout, prior_mean, prior_cov, new_mean, new_cov) -> int:
    """Predict + update of the run ``mean (1, n)``, ``cov (1, n, n)`` by ``z (1, m)`` into
    ``new_mean``, ``new_cov`` (``prior_*`` the predicted belief); returns a status code."""
    w_predict, w_update, args, noise, r_cov, state_angles, z_angles = _unpack(consts, layout)
    model = layout[_MODEL]
    if layout[_AUGMENTED]:
        status = ukf.noisy_predict_builtin(
            model, mean, cov, args, noise, w_predict, state_angles, prior_mean, prior_cov
        )
    else:
        status = ukf.predict_builtin(
            model, mean, cov, args, noise, w_predict, state_angles, prior_mean, prior_cov
        )
    if status != OK:
        return status
    return ukf.update_leading_entries(
        prior_mean,
        prior_cov,
        z,
        args,
        r_cov,
        w_update,
        state_angles,
        z_angles,
        new_mean,
        new_cov,
    )


@numba.njit(cache=True)
def _ekf_once(mean, cov, z, consts, layout, prior_mean, prior_cov, new_mean, new_cov) -> int:
    """As :func:`_ukf_once` for the EKF (additive noise, Joseph-form update)."""
    _, _, args, noise, r_cov, state_angles, z_angles = _unpack(consts, layout)
    status = ekf.predict_builtin(
        layout[_MODEL], mean, cov, args, noise, state_angles, prior_mean, prior_cov
    )
    if status != OK:
        return status
    return ekf.update_leading_entries(
        prior_mean, prior_cov, z, args, r_cov, state_angles, z_angles, new_mean, new_cov
    )


@numba.njit(cache=True)
def _accept(t, run_mean, run_cov, new_mean, new_cov, means_out, covs_out) -> None:
    """Step ``t`` succeeded: its belief becomes the state, and row ``t`` of the record when
    there is one (``means_out (T, n)``, ``covs_out (T, n, n)``; no rows: no record)."""
    run_mean[:] = new_mean
    run_cov[:] = new_cov
    if means_out.shape[0] > 0:
        means_out[t] = new_mean[0]
        covs_out[t] = new_cov[0]


@numba.njit(cache=True)
def _work_views(work, n):
    """The beliefs kept in a filter's work array ``(3 (n + n^2),)``: the state, the predicted
    and the updated belief, each as ``mean (1, n)``, ``cov (1, n, n)``."""
    size = n + n * n
    views = []
    for part in range(3):
        start = part * size
        views.append(
            (
                work[start : start + n].reshape((1, n)),
                work[start + n : start + size].reshape((1, n, n)),
            )
        )
    return views[0], views[1], views[2]


@numba.njit(cache=True)
def ukf_step(work, z, consts, layout) -> int:
    """One UKF predict + update of the state held in ``work`` (:func:`_work_views`; overwritten
    on success) by ``z (m,)``, with the constants of :func:`pack`; returns a status code. The
    work array spares the step its allocations and an argument."""
    (mean, cov), (prior_mean, prior_cov), (new_mean, new_cov) = _work_views(work, layout[_N])
    status = _ukf_once(
        mean,
        cov,
        z.reshape((1, z.shape[0])),
        consts,
        layout,
        prior_mean,
        prior_cov,
        new_mean,
        new_cov,
    )
    if status == OK:
        mean[:] = new_mean
        cov[:] = new_cov
    return status


@numba.njit(cache=True)
def ekf_step(work, z, consts, layout) -> int:
    """As :func:`ukf_step` for the EKF."""
    (mean, cov), (prior_mean, prior_cov), (new_mean, new_cov) = _work_views(work, layout[_N])
    status = _ekf_once(
        mean,
        cov,
        z.reshape((1, z.shape[0])),
        consts,
        layout,
        prior_mean,
        prior_cov,
        new_mean,
        new_cov,
    )
    if status == OK:
        mean[:] = new_mean
        cov[:] = new_cov
    return status


@numba.njit(cache=True)
def ukf_run(mean, cov, zs, consts, layout, means_out, covs_out):
    """The UKF over the measurements ``zs (T, m)`` in one call from ``mean (n,)``, ``cov (n, n)``
    (left at the last good belief); each updated belief into ``means_out (T, n)``,
    ``covs_out (T, n, n)``. Returns ``(status, steps done)``."""
    n, m = mean.shape[0], zs.shape[1]
    run_mean, run_cov = mean.reshape((1, n)), cov.reshape((1, n, n))
    prior_mean, prior_cov = np.empty((1, n)), np.empty((1, n, n))
    new_mean, new_cov = np.empty((1, n)), np.empty((1, n, n))
    for t in range(zs.shape[0]):
        status = _ukf_once(
            run_mean,
            run_cov,
            zs[t].reshape((1, m)),
            consts,
            layout,
            prior_mean,
            prior_cov,
            new_mean,
            new_cov,
        )
        if status != OK:
            return status, t
        _accept(t, run_mean, run_cov, new_mean, new_cov, means_out, covs_out)
    return OK, zs.shape[0]


@numba.njit(cache=True)
def ekf_run(mean, cov, zs, consts, layout, means_out, covs_out):
    """As :func:`ukf_run` for the EKF."""
    n, m = mean.shape[0], zs.shape[1]
    run_mean, run_cov = mean.reshape((1, n)), cov.reshape((1, n, n))
    prior_mean, prior_cov = np.empty((1, n)), np.empty((1, n, n))
    new_mean, new_cov = np.empty((1, n)), np.empty((1, n, n))
    for t in range(zs.shape[0]):
        status = _ekf_once(
            run_mean,
            run_cov,
            zs[t].reshape((1, m)),
            consts,
            layout,
            prior_mean,
            prior_cov,
            new_mean,
            new_cov,
        )
        if status != OK:
            return status, t
        _accept(t, run_mean, run_cov, new_mean, new_cov, means_out, covs_out)
    return OK, zs.shape[0]


# -------------------------------------------------------------------------- the Python side


def pack(
    process: ProcessModel,
    measurement: MeasurementModel,
    n: int,
    state_angles: tuple[int, ...],
    args: tuple,
    weights: tuple | None,
    owner: str,
) -> tuple[np.ndarray, np.ndarray]:
    """``(consts, layout)`` of a lean filter (module docstring), or an :class:`EstimationError`
    naming what the lean path cannot take. ``weights``: the predict and update
    :class:`~localization.sigma_points.SigmaWeights` (UKF) or ``None`` (EKF)."""
    augmented = process.noise == ProcessNoise.AUGMENTED
    if weights is not None:
        found = ukf.PREDICT_ENTRIES.get((process.point, augmented))
    else:
        found = ekf.PREDICT_ENTRIES.get((process.point, process.jacobian_point))
    if found is None or found[1] < 0 or (weights is None and augmented):
        raise EstimationError(
            f"{owner}: the process model must be a built-in motion model "
            "(CV, CTRV, CTRA or CCA .process_model(Q); the EKF additive)"
        )
    if measurement.point is not motion.leading_entries_point or (
        weights is None and measurement.jacobian_point is not motion.leading_entries_jacobian_point
    ):
        raise EstimationError(
            f"{owner}: the measurement model must be gps_model(R) or pose_model(R)"
        )
    model = found[1]
    if n != STATE_DIMENSIONS[model]:
        raise EstimationError(
            f"{owner}: the belief has {n} states, the process model {STATE_DIMENSIONS[model]}"
        )
    noise = process.noise_sqrt if augmented else process.Q
    r_cov = measurement.R
    m = r_cov.shape[-1]
    if noise.ndim != 2 or r_cov.ndim != 2:
        raise EstimationError(f"{owner}: Q and R must be shared matrices (k, k), not per run")
    if m > n:
        raise EstimationError(f"{owner}: {m} measurements of {n} states")
    packed = pack_args(args, ())
    if packed is None or packed.shape[0] != 1 or not np.isfinite(packed).all():
        raise EstimationError(f"{owner}: the step arguments must be finite numbers, got {args!r}")
    weight_values = (
        np.zeros(_WEIGHTS)
        if weights is None
        else np.concatenate([weights[0].packed, weights[1].packed])
    )
    consts = np.concatenate([weight_values, packed[0], noise.ravel(), r_cov.ravel()])
    layout = np.array(
        [
            model,
            int(augmented),
            n,
            m,
            packed.shape[1],
            noise.shape[-1],
            len(state_angles),
            len(measurement.angle_indices),
            *state_angles,
            *measurement.angle_indices,
        ],
        dtype=np.int64,
    )
    return consts, layout


class _LeanFilter:
    """The state and the Python side shared by :class:`LeanUKF` and :class:`LeanEKF`."""

    _owner = "lean filter"
    _step_entry = staticmethod(ukf_step)
    _run_entry = staticmethod(ukf_run)

    def __init__(self, belief: Gaussian, consts: np.ndarray, layout: np.ndarray) -> None:
        self._angles = belief.angle_indices
        n = belief.mean.shape[0]
        self._work = np.zeros(3 * (n + n * n))  # the state, then scratch (_work_views)
        self._mean = self._work[:n]
        self._cov = self._work[n : n + n * n].reshape(n, n)
        self._mean[:] = belief.mean
        self._cov[:] = belief.cov
        self._consts, self._layout = consts, layout
        self._z_shape = (int(layout[_M]),)
        # the entry and its fixed arguments as instance attributes: a step looks up nothing else
        self._entry = self._step_entry
        self.mean = self._mean.view()
        """``(n,)`` the current mean, a read-only view (it changes with every step)."""
        self.mean.flags.writeable = False
        self.cov = self._cov.view()
        """``(n, n)`` the current covariance, a read-only view."""
        self.cov.flags.writeable = False

    @staticmethod
    def _one_run(belief: Gaussian, owner: str) -> int:
        if belief.mean.ndim != 1:
            raise EstimationError(
                f"{owner}: one run (n,) only, got a belief of shape {belief.mean.shape}; "
                "batches step through the filter's predict and update"
            )
        return belief.mean.shape[0]

    @property
    def belief(self) -> Gaussian:
        """The current belief (a copy)."""
        return Gaussian(self._mean.copy(), self._cov.copy(), self._angles)

    def _failed(self, status: int, step: int | None) -> EstimationError:
        where = "" if step is None else f" at step {step}"
        reason = (
            "a covariance to factorise (P or S) is not positive definite"
            if status == NOT_POSITIVE_DEFINITE
            else "a measurement or result is not finite (NaN or inf)"
        )
        return EstimationError(f"{self._owner}{where}: {reason}; the state is that before it")

    def step(self, z: np.ndarray) -> None:
        """Predict, then update by ``z (m,)`` (a float64 array), in place.

        Raises:
            EstimationError: ``z`` of another shape, or a failed step (module docstring).
        """
        if z.__class__ is not np.ndarray or z.dtype is not _F64 or z.shape != self._z_shape:
            z = self._measurements(z, 1)
        status = self._entry(self._work, z, self._consts, self._layout)
        if status:
            raise self._failed(status, None)

    def run(self, zs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The steps over ``zs (T, m)`` in one compiled call; returns the updated means
        ``(T, n)`` and covariances ``(T, n, n)``; the state ends at the last step.

        Raises:
            EstimationError: ``zs`` of another shape, or a failed step ``t`` (the state is then
                the belief after step ``t - 1``).
        """
        zs = self._measurements(zs, 2)
        n = self._mean.shape[0]
        means, covs = np.empty((zs.shape[0], n)), np.empty((zs.shape[0], n, n))
        status, done = self._run_entry(
            self._mean, self._cov, zs, self._consts, self._layout, means, covs
        )
        if status:
            raise self._failed(status, done)
        return means, covs

    def _measurements(self, values, ndim: int) -> np.ndarray:
        """``values`` as a writable C-contiguous float64 array ``(m,)`` (``ndim`` 1) or
        ``(T, m)`` (``ndim`` 2), or an :class:`EstimationError`."""
        values = np.ascontiguousarray(values, dtype=np.float64)
        m = self._z_shape[0]
        if values.ndim != ndim or values.shape[-1] != m:
            expected = f"({m},)" if ndim == 1 else f"(T, {m})"
            raise EstimationError(
                f"{self._owner}: the measurements must have shape {expected}, got {values.shape}"
            )
        if not values.flags.writeable:
            values = values.copy()
        return values


class LeanUKF(_LeanFilter):
    """One UKF run of a built-in motion model, stepped in place (module docstring).

    Args:
        ukf: the :class:`~localization.ukf.UnscentedKalmanFilter` whose sigma points to use.
        process: a built-in model's ``process_model(Q)``, additive or augmented noise.
        measurement: :func:`~localization.motion_models.gps_model` or
            :func:`~localization.motion_models.pose_model`.
        belief: the initial belief, one run ``(n,)``; its angle indices are kept.
        *args: the prediction's arguments (``dt_s``), fixed for the filter's life.
    """

    _owner = "LeanUKF"

    def __init__(self, ukf, process, measurement, belief: Gaussian, *args) -> None:
        n = self._one_run(belief, self._owner)
        dim = n + process.Q.shape[-1] if process.noise == ProcessNoise.AUGMENTED else n
        weights = (ukf.points.weights(dim), ukf.points.weights(n))
        consts, layout = pack(
            process, measurement, n, belief.angle_indices, args, weights, self._owner
        )
        super().__init__(belief, consts, layout)


class LeanEKF(_LeanFilter):
    """One EKF run of a built-in motion model (additive noise), stepped in place (module
    docstring); the arguments as :class:`LeanUKF`'s, without the filter settings."""

    _owner = "LeanEKF"
    _step_entry = staticmethod(ekf_step)
    _run_entry = staticmethod(ekf_run)

    def __init__(self, process, measurement, belief: Gaussian, *args) -> None:
        n = self._one_run(belief, self._owner)
        consts, layout = pack(
            process, measurement, n, belief.angle_indices, args, None, self._owner
        )
        super().__init__(belief, consts, layout)
