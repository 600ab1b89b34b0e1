"""One filter stepped in place: a compiled call per step, or one call for a whole sequence.

:class:`~localization.ukf.UnscentedKalmanFilter` and
:class:`~localization.ekf.ExtendedKalmanFilter` take immutable beliefs and any batch, so each
step checks its inputs, packs its arguments and builds two result beliefs around its two
compiled calls: for one CTRV filter that Python is most of a 14 us step. :class:`LeanUKF` and
:class:`LeanEKF` hold one run of a known model instead: everything about the model (the
kernels, ``Q``, ``R``, the sigma weights, the step's arguments, the angle indices) is checked
and packed once, at construction, into a work array and a layout; a step is then one compiled
call (:func:`ukf_step`, :func:`ekf_step`) of three arguments, the work array, ``z`` and the
layout, which computes in the work array's scratch (it allocates nothing) and overwrites the
filter's state there::

    lean = LeanUKF(UnscentedKalmanFilter(), CTRV.process_model(Q), pose_model(R), belief, dt_s)
    for z in measurements:        # z (m,) float64
        lean.step(z)              # predict + update, in place
    lean.mean, lean.cov           # read-only views of the state
    means, covs = lean.run(zs)    # zs (T, m): T steps in one call, (T, n) and (T, n, n)

The arithmetic is that of the batched steps, the same per-run functions
(:func:`localization.compiled.ukf.predict_run`, ``augmented_predict_run`` and ``update_run``,
the EKF's likewise) on one run, so a lean step equals the
:class:`~localization.ukf.UnscentedKalmanFilter` step on the same belief bit for bit (tested).
What the lean filters do not do: batches (a batch already pays its Python once per step for
all runs), user kernels (the built-in motion models of :mod:`localization.motion_models` with
the GPS or pose measurement), and the :class:`~localization.linalg.PDPolicy` repairs: a
covariance that is not positive definite, or a non-finite measurement or result, raises an
:class:`~localization.errors.EstimationError` and leaves the state as it was before the failing
step.

Packing (:func:`pack`). ``layout`` (int64): the process kernel's number
(:data:`localization.compiled.motion.MODEL_NUMBERS`), augmented (0/1), ``n``, ``m``, the
number ``k`` of packed step arguments, the noise dimension ``q`` (``n`` additive), the counts of
state and measurement angle indices, then those indices. The work array (float64,
:func:`work_length`): first the constants, the predict and update sigma weights
``(gamma, W_i, c0)`` (zeros for the EKF), the step arguments ``(k,)``, the process noise
(``Q (n, n)`` additive, its square root ``S (q, q)`` augmented) and ``R (m, m)``, flattened
(:func:`_constants`); then the state, ``mean (n,)`` and ``cov (n, n)`` (:func:`_state`); then
the predicted and the updated belief (``prior_mean, new_mean, prior_cov, new_cov`` as rows of
one ``(2 + 2n, n)`` block) and the scratch of the filter's predict and update, as long as
the filter module says (``predict_scratch_length``, ``update_scratch_length``), which its run
functions carve (the ``views`` of :func:`_filter_step`). A step writes the predicted and
updated beliefs and copies the updated one onto the state only when it succeeded.

Measurements. The step entries are compiled for one set of argument types only
(:func:`_sealed`): a ``z`` that is not a writable C-contiguous float64 vector (strided,
read-only, another dtype, a list) is copied into one by :meth:`LeanUKF.step` rather than
making numba compile the entry again for it, which would take about a minute; the length of
``z`` is checked in the compiled step (:data:`localization.compiled.glue.WRONG_SIZE`).
"""

from __future__ import annotations

import numba
import numpy as np

from localization.compiled import ekf, motion, ukf
from localization.compiled.batch import borrow, carve
from localization.compiled.glue import NOT_POSITIVE_DEFINITE, OK, WRONG_SIZE, pack_args
from localization.errors import EstimationError
from localization.gaussian import Gaussian
from localization.models import MeasurementModel, ProcessModel, ProcessNoise

# layout entries
_MODEL, _AUGMENTED, _N, _M, _K, _Q, _STATE_ANGLES, _MEASUREMENT_ANGLES = range(8)
_HEADER = 8
#: work array entries before the step arguments: the predict and the update weights
_WEIGHTS = 6

#: State dimension of each built-in process kernel, by its number.
STATE_DIMENSIONS = {
    motion.MODEL_NUMBERS["CV"]: 4,
    motion.MODEL_NUMBERS["CTRV"]: 5,
    motion.MODEL_NUMBERS["CTRA"]: 6,
    motion.MODEL_NUMBERS["CCA"]: 6,
}


# ------------------------------------------------------------------------ compiled entries


@numba.njit(inline="always")
def _constants(work, layout):
    """Views of the constants at the head of ``work`` (module docstring): ``(predict weights
    (3,), update weights (3,), args (k,), noise (q, q), R (m, m), state angles, measurement
    angles, end)``."""
    m, k, q = layout[_M], layout[_K], layout[_Q]
    first = _HEADER + layout[_STATE_ANGLES]
    state_angles = layout[_HEADER:first]
    measurement_angles = layout[first : first + layout[_MEASUREMENT_ANGLES]]
    args = work[_WEIGHTS : _WEIGHTS + k]
    noise, start = carve(work, _WEIGHTS + k, q, q)
    r_cov, start = carve(work, start, m, m)
    return (
        work[0:3],
        work[3:6],
        args,
        noise,
        r_cov,
        state_angles,
        measurement_angles,
        start,
    )


@numba.njit(inline="always")
def _state(work, start, n):
    """The state from ``start``: ``(mean (n,), cov (n, n), end)``."""
    cov, end = carve(work, start + n, n, n)
    return work[start : start + n], cov, end


# The arguments are spelled out, not passed on as ``*args`` (:mod:`localization.compiled.batch`).


@numba.njit
def _ukf_predict(model, augmented, x, prior, args, noise, weights, angles, out_mean, out_cov, s):
    """The UKF's built-in prediction of one run, additive or augmented noise."""
    if augmented:
        run = ukf.builtin_augmented_predict_run
        return run(model, x, prior, args, noise, weights, angles, out_mean, out_cov, s)
    run = ukf.builtin_predict_run
    return run(model, x, prior, args, noise, weights, angles, out_mean, out_cov, s)


@numba.njit
def _ekf_predict(model, augmented, x, prior, args, noise, weights, angles, out_mean, out_cov, s):
    """The EKF's built-in prediction of one run (additive noise: ``augmented`` is 0)."""
    return ekf.builtin_predict_run(
        model, x, prior, args, noise, weights, angles, out_mean, out_cov, s
    )


def _filter_step(predict, update, predict_length, update_length):
    """``(views, step)``, compiled, of a filter whose one-run prediction is ``predict(model,
    augmented, *run_args)`` and update ``update(*run_args)`` (the arguments of
    :mod:`localization.compiled.batch`), their scratch ``predict_length(n, q)`` and
    ``update_length(n, m)`` floats. ``views(work, layout)``: ``(constants (as
    :func:`_constants`), (mean, cov), beliefs (2 + 2n, n), (predict scratch, update scratch),
    end)``; ``step(work, z, layout)``: the step of :func:`ukf_step`. A factory for the reason of
    :mod:`localization.compiled.batch`."""

    @numba.njit(inline="always")
    def views(work, layout):
        n, m, q = layout[_N], layout[_M], layout[_Q]
        constants = _constants(work, layout)
        mean, cov, start = _state(work, constants[-1], n)
        beliefs, start = carve(work, start, 2 + 2 * n, n)
        middle = start + predict_length(n, q)
        end = middle + update_length(n, m)
        return constants[:-1], (mean, cov), beliefs, (work[start:middle], work[middle:end]), end

    @numba.njit
    def step(work, z, layout) -> int:
        if z.shape[0] != layout[_M]:
            return WRONG_SIZE
        work, z, layout = borrow(work), borrow(z), borrow(layout)  # the arguments: alive
        constants, (mean, cov), beliefs, (predict_scratch, update_scratch), _ = views(work, layout)
        w_predict, w_update, args, noise, r_cov, state_angles, z_angles = constants
        n = mean.shape[0]
        prior_mean, new_mean, prior_cov, new_cov = (
            beliefs[0],
            beliefs[1],
            beliefs[2 : 2 + n],
            beliefs[2 + n :],
        )
        status = predict(
            layout[_MODEL],
            layout[_AUGMENTED],
            mean,
            cov,
            args,
            noise,
            w_predict,
            state_angles,
            prior_mean,
            prior_cov,
            predict_scratch,
        )
        if status == OK:
            status = update(
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
                update_scratch,
            )
        if status == OK:
            mean[:] = new_mean
            cov[:] = new_cov
        return status

    return views, step


ukf_views, _ukf_step = _filter_step(
    _ukf_predict,
    ukf.leading_entries_update_run,
    ukf.predict_scratch_length,
    ukf.update_scratch_length,
)
ekf_views, _ekf_step = _filter_step(
    _ekf_predict,
    ekf.leading_entries_update_run,
    ekf.predict_scratch_length,
    ekf.update_scratch_length,
)


@numba.njit(cache=True)
def ukf_step(work, z, layout) -> int:
    """One UKF predict + update of the state held in ``work`` (module docstring; overwritten
    on success) by ``z (m,)``; returns a status code (:data:`WRONG_SIZE` for a ``z`` of another
    length). Everything the step needs is in ``work`` and ``layout``: it allocates nothing."""
    return _ukf_step(work, z, layout)


@numba.njit(cache=True)
def ekf_step(work, z, layout) -> int:
    """As :func:`ukf_step` for the EKF (additive noise, Joseph-form update)."""
    return _ekf_step(work, z, layout)


def _sequence(step):
    """The compiled ``run(work, zs (T, m), layout, means_out (T, n), covs_out (T, n, n))``:
    ``step`` (:func:`ukf_step`, :func:`ekf_step`) over the measurements ``zs``, each updated
    belief into row ``t`` of the outputs; the state is left at the last good belief. Returns
    ``(status, steps done)``. A factory for the reason of
    :func:`localization.compiled.ukf.batched_predict`."""

    @numba.njit
    def run(work, zs, layout, means_out, covs_out):
        mean, cov, _ = _state(work, _constants(work, layout)[-1], layout[_N])
        for t in range(zs.shape[0]):
            status = step(work, zs[t], layout)
            if status != OK:
                return status, t
            means_out[t] = mean
            covs_out[t] = cov
        return OK, zs.shape[0]

    return run


_ukf_sequence = _sequence(ukf_step)
_ekf_sequence = _sequence(ekf_step)


@numba.njit(cache=True)
def ukf_run(work, zs, layout, means_out, covs_out):
    """:func:`ukf_step` over a sequence of measurements in one call (:func:`_sequence`)."""
    return _ukf_sequence(work, zs, layout, means_out, covs_out)


@numba.njit(cache=True)
def ekf_run(work, zs, layout, means_out, covs_out):
    """:func:`ekf_step` over a sequence of measurements in one call (:func:`_sequence`)."""
    return _ekf_sequence(work, zs, layout, means_out, covs_out)


def work_length(layout: np.ndarray, unscented: bool) -> int:
    """The length of a filter's work array (:func:`_constants`, :func:`_state`, the beliefs,
    the scratch of the filter's predict and update: the ``views`` of :func:`_filter_step`)."""
    n, m, k, q = (int(layout[i]) for i in (_N, _M, _K, _Q))
    lengths = ukf if unscented else ekf
    head = _WEIGHTS + k + q * q + m * m + n + n * n + (2 + 2 * n) * n
    return head + lengths.predict_scratch_length(n, q) + lengths.update_scratch_length(n, m)


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
    """``(consts, layout)`` of a lean filter: the constants at the head of its work array and
    its layout (module docstring), or an :class:`EstimationError` naming what the lean path
    cannot take. ``weights``: the predict and update
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


#: The types of the step entries' arguments ``(work, z, layout)``: C-contiguous, writable.
_STEP_TYPES = (numba.float64[::1], numba.float64[::1], numba.int64[::1])


def _sealed(entry):
    """``entry`` (:func:`ukf_step`, :func:`ekf_step`) compiled, or loaded from numba's disk
    cache, for :data:`_STEP_TYPES`, and for nothing else: from then on a ``z`` of another
    type (strided, read-only, another dtype, a list) makes a call raise ``TypeError``, which
    :meth:`_LeanFilter.step` answers with a copy, instead of numba compiling the entry again
    for it (about a minute); the step checks no type itself."""
    if entry not in _SEALED:
        entry.compile(_STEP_TYPES)
        entry.disable_compile()
        _SEALED.add(entry)
    return entry


_SEALED: set = set()


class _LeanFilter:
    """The state and the Python side shared by :class:`LeanUKF` and :class:`LeanEKF`."""

    _owner = "lean filter"
    _unscented = True
    _step_entry = staticmethod(ukf_step)
    _run_entry = staticmethod(ukf_run)

    def __init__(self, belief: Gaussian, consts: np.ndarray, layout: np.ndarray) -> None:
        self._angles = belief.angle_indices
        n = belief.mean.shape[0]
        # the constants, the state, the predicted and updated beliefs, the scratch
        self._work = np.zeros(work_length(layout, self._unscented))
        self._work[: consts.shape[0]] = consts
        start = consts.shape[0]
        self._mean = self._work[start : start + n]
        self._cov = self._work[start + n : start + n + n * n].reshape(n, n)
        self._mean[:] = belief.mean
        self._cov[:] = belief.cov
        self._layout = layout
        # the entry as an instance attribute: a step looks up nothing else
        self._entry = _sealed(self._step_entry)
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

    def _failed(self, status: int, step: int | None, z=None) -> EstimationError:
        """The error of a failed step (``z`` the measurement of a single step)."""
        if status == WRONG_SIZE:
            return self._shape_error(np.shape(z), 1)
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
        try:
            status = self._entry(self._work, z, self._layout)
        except TypeError:  # not a writable C-contiguous float64 vector: refused (_sealed)
            status = self._entry(self._work, self._measurements(z, 1), self._layout)
        if status:
            raise self._failed(status, None, z)

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
        status, done = self._run_entry(self._work, zs, self._layout, means, covs)
        if status:
            raise self._failed(status, done)
        return means, covs

    def _measurements(self, values, ndim: int) -> np.ndarray:
        """``values`` as a writable C-contiguous float64 array ``(m,)`` (``ndim`` 1) or
        ``(T, m)`` (``ndim`` 2), or an :class:`EstimationError`."""
        values = np.ascontiguousarray(values, dtype=np.float64)
        if values.ndim != ndim or values.shape[-1] != self._layout[_M]:
            raise self._shape_error(values.shape, ndim)
        if not values.flags.writeable:
            values = values.copy()
        return values

    def _shape_error(self, shape: tuple[int, ...], ndim: int) -> EstimationError:
        m = int(self._layout[_M])
        expected = f"({m},)" if ndim == 1 else f"(T, {m})"
        return EstimationError(
            f"{self._owner}: the measurements must have shape {expected}, got {shape}"
        )


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
    _unscented = False
    _step_entry = staticmethod(ekf_step)
    _run_entry = staticmethod(ekf_run)

    def __init__(self, process, measurement, belief: Gaussian, *args) -> None:
        n = self._one_run(belief, self._owner)
        consts, layout = pack(
            process, measurement, n, belief.angle_indices, args, None, self._owner
        )
        super().__init__(belief, consts, layout)
