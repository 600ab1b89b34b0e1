"""The compiled EKF step (numba): one call per predict or update, whatever the batch size.

Why compiled. A numpy EKF step on 5 states is a few dozen numpy calls on tiny arrays plus the
batched model and Jacobian evaluated on one state, each about 1 us of call overhead: about
150 us for one CTRV filter (``benchmarks/filters.py``), where the arithmetic needs well under
a microsecond. Here a step is one call of a compiled entry that loops over the runs in scalar
code and calls the per-point model and Jacobian kernels once per run.
:class:`~localization.ekf.ExtendedKalmanFilter` (and the prediction of the iterated EKF) uses
it whenever the model carries both kernels (``point=`` and ``jacobian_point=`` of
:class:`~localization.models.ProcessModel` and :class:`~localization.models.MeasurementModel`)
with additive noise and the step can be expressed here; otherwise, and whenever a step
fails, the numpy path of :mod:`localization.ekf` runs, which stays the reference (same
results to rounding, tested in ``tests/localization/test_compiled_ekf.py``).

The maths is that of :mod:`localization.ekf`, term by term::

    predict:  F = F(x),  x- = f(x) (angles wrapped),  P- = sym((F P) F^T + Q)
    update:   H = H(x),  y = z - h(x) (angles wrapped),  C = P H^T,  S = H C + R
              K^T = S^-1 C^T (Cholesky solve; the numpy path solves by LU),
              x+ = x + K y (angles wrapped),  A = I - K H,
              P+ = sym((A P) A^T + (K R) K^T)                         (Joseph form)

with ``sym(M) = (M + M^T) / 2``. Kernel conventions (the per-point kernels of
:mod:`localization.compiled.ukf`): ``f(x (n,), args (k,), out (n,))``,
``F(x (n,), args (k,), out (n, n))``, ``h(x (n,), args (k,), out (m,))``,
``H(x (n,), args (k,), out (m, n))``, with ``args`` the step's arguments packed as floats
(:func:`localization.compiled.glue.pack_args`).

Entries. As in :mod:`localization.compiled.ukf`: each step is written once for one run
(:func:`predict_run`, :func:`update_run`, kernels and scratch passed in), a batch loops a run
function over its runs (:mod:`localization.compiled.batch`, the UKF's loop), the lean EKF calls
the run functions on its own scratch; the entries Python calls are module-level and cached on
disk for the built-in kernels (one prediction entry switches between the four motion models by
their number in :data:`BUILTIN_PROCESS_KERNELS`); a user's own kernels get an uncached entry,
built once per pair of kernels (:func:`predict_entry`, :func:`update_entry`).

Status codes, array conventions and the Python-side helpers are those of
:mod:`localization.compiled.glue`: ``OK``, ``NOT_POSITIVE_DEFINITE`` (``S``) or ``NOT_FINITE``
(an argument, ``z`` or a result); on anything but
``OK`` the caller runs the numpy step, which gives its own results, errors and warnings.
Runs are independent and computed by the same code, so a batch gives its runs' one-by-one
results bit for bit.
"""

from __future__ import annotations

import numba
import numpy as np
from numba.extending import register_jitable

from localization.compiled import motion
from localization.compiled.batch import batched_predict, batched_update, carve
from localization.compiled.glue import (
    NOT_FINITE,
    NOT_POSITIVE_DEFINITE,
    OK,
    angle_array,
    call_entry,
    entry_arrays,
    read_only,
)
from localization.compiled.linalg import (
    all_finite,
    kalman_gain_t,
    symmetrise_in_place,
    wrap_angle,
)

# ------------------------------------------------------------------------------- the cores


@numba.njit(cache=True)
def _sandwich(left, middle, temp, out) -> None:
    """``out (r, r) = (left middle) left^T`` with ``left (r, c)``, ``middle (c, c)``, ``temp (r, c)``."""
    rows, cols = left.shape
    for i in range(rows):
        for j in range(cols):
            total = 0.0
            for k in range(cols):
                total += left[i, k] * middle[k, j]
            temp[i, j] = total
    for i in range(rows):
        for j in range(rows):
            total = 0.0
            for k in range(cols):
                total += temp[i, k] * left[j, k]
            out[i, j] = total


@numba.njit
def _finish(new_mean, new_cov, addend) -> int:
    """``new_cov (n, n) = sym(new_cov + addend)`` (``Q``, or the update's ``(K R) K^T``); the
    status of the belief ``(new_mean, new_cov)``."""
    n = new_cov.shape[0]
    for i in range(n):
        for j in range(n):
            new_cov[i, j] += addend[i, j]
    symmetrise_in_place(new_cov)
    if not (all_finite(new_mean) and all_finite(new_cov)):
        return NOT_FINITE
    return OK


# As in localization.compiled.ukf: each step is written once per run (``*_run``, its scratch
# passed in as one float array that it carves), with the arguments of the UKF's runs
# (:mod:`localization.compiled.batch` loops either over a batch), the lean entries call the run
# functions on the filter's own scratch.


@register_jitable
def predict_scratch_length(n, q):
    """The floats of a prediction's scratch (:func:`predict_run`) of ``n`` states (``q = n``,
    the noise dimension :mod:`localization.compiled.batch` passes)."""
    return (1 + 2 * n) * n


@register_jitable
def update_scratch_length(n, m):
    """The floats of the scratch of an update (:func:`update_run`) of ``n`` states by ``m``
    measurements."""
    return (1 + 2 * m + 3 * n) * n + (2 + 3 * n + 2 * m) * m


@numba.njit
def predict_run(
    f, jac_f, x, prior, step_args, q, weights, angles, new_mean, new_cov, scratch
) -> int:
    """EKF prediction of one run (module docstring), ``f(x, args, out)``, ``F(x, args, out)``.

    ``x (n,)``, ``prior (n, n)``, ``step_args (k,)``, ``q (n, n)``, ``weights`` unused (the
    arguments of :mod:`localization.compiled.batch`, which the UKF's sigma weights take),
    ``angles`` the state's angle indices (int64), ``scratch (predict_scratch_length(n, n),)``;
    writes ``new_mean (n,)``, ``new_cov (n, n)``. Returns a status code.
    """
    n = x.shape[0]
    rows, _ = carve(scratch, 0, 1 + 2 * n, n)
    point, jac, temp = rows[0], rows[1 : 1 + n], rows[1 + n :]
    point[:] = x
    jac_f(point, step_args, jac)
    point[:] = x
    f(point, step_args, new_mean)
    for a in angles:
        new_mean[a] = wrap_angle(new_mean[a])
    _sandwich(jac, prior, temp, new_cov)  # (F P) F^T
    return _finish(new_mean, new_cov, q)


@numba.njit
def update_run(
    h, jac_h, x, prior, z, step_args, r, weights, state_angles, angles, new_mean, new_cov, scratch
) -> int:
    """EKF update of one run in Joseph form (module docstring), ``h(x, args, out)``, ``H(x, args, out)``.

    ``x (n,)``, ``prior (n, n)``, ``z (m,)``, ``step_args (k,)``, ``r (m, m)``, ``weights``
    unused (as :func:`predict_run`), ``state_angles`` and ``angles`` (the measurement's) angle
    indices (int64), ``scratch (update_scratch_length(n, m),)``; writes ``new_mean (n,)``,
    ``new_cov (n, n)``. Returns a status code.
    """
    n, m = x.shape[0], z.shape[0]
    rows_n, end = carve(scratch, 0, 1 + 2 * m + 3 * n, n)
    point, jac, gain_t = rows_n[0], rows_n[1 : 1 + m], rows_n[1 + m : 1 + 2 * m]
    square = rows_n[1 + 2 * m :]
    joseph, temp, noise_part = square[:n], square[n : 2 * n], square[2 * n :]
    rows_m, _ = carve(scratch, end, 2 + 3 * n + 2 * m, m)
    z_pred, innovation, tall = rows_m[0], rows_m[1], rows_m[2 : 2 + 3 * n]
    cross, gain, temp_noise = tall[:n], tall[n : 2 * n], tall[2 * n :]
    s_cov, s_chol = rows_m[2 + 3 * n : 2 + 3 * n + m], rows_m[2 + 3 * n + m :]
    if not all_finite(z):
        return NOT_FINITE
    point[:] = x
    h(point, step_args, z_pred)
    for c in range(m):
        innovation[c] = z[c] - z_pred[c]
    for a in angles:
        innovation[a] = wrap_angle(innovation[a])
    point[:] = x
    jac_h(point, step_args, jac)
    if not kalman_gain_t(prior, jac, r, cross, s_cov, s_chol, gain_t):  # K^T = S^-1 (P H^T)^T
        return NOT_POSITIVE_DEFINITE
    for i in range(n):  # x+ = x + K y
        total = 0.0
        for c in range(m):
            total += gain_t[c, i] * innovation[c]
        new_mean[i] = x[i] + total
        for c in range(m):
            gain[i, c] = gain_t[c, i]
    for a in state_angles:
        new_mean[a] = wrap_angle(new_mean[a])
    for i in range(n):  # A = I - K H
        for j in range(n):
            total = 0.0
            for c in range(m):
                total += gain[i, c] * jac[c, j]
            joseph[i, j] = (1.0 if i == j else 0.0) - total
    _sandwich(joseph, prior, temp, new_cov)  # (A P) A^T
    _sandwich(gain, r, temp_noise, noise_part)  # (K R) K^T
    return _finish(new_mean, new_cov, noise_part)


# ------------------------------------------------------------------- cached built-in entries
# As in localization.compiled.ukf: module-level entries (cached on disk), kernels named as
# module attributes so that numba resolves them to constants, no function arguments.

#: The built-in process kernels ``(f, F)``, by the number :func:`predict_builtin` switches on.
BUILTIN_PROCESS_KERNELS = (
    (motion.cv_point, motion.cv_jacobian_point),
    (motion.ctrv_point, motion.ctrv_jacobian_point),
    (motion.ctra_point, motion.ctra_jacobian_point),
    (motion.cca_point, motion.cca_jacobian_point),
)


# The kernels are passed by name in each call, as in localization.compiled.ukf.


@numba.njit
def builtin_predict_run(model, x, prior, step_args, q, weights, angles, new_mean, new_cov, s):
    """:func:`predict_run` with the kernels number ``model`` of :data:`BUILTIN_PROCESS_KERNELS`."""
    run = predict_run
    if model == 0:
        f, jac_f = motion.cv_point, motion.cv_jacobian_point
        return run(f, jac_f, x, prior, step_args, q, weights, angles, new_mean, new_cov, s)
    if model == 1:
        f, jac_f = motion.ctrv_point, motion.ctrv_jacobian_point
        return run(f, jac_f, x, prior, step_args, q, weights, angles, new_mean, new_cov, s)
    if model == 2:
        f, jac_f = motion.ctra_point, motion.ctra_jacobian_point
        return run(f, jac_f, x, prior, step_args, q, weights, angles, new_mean, new_cov, s)
    f, jac_f = motion.cca_point, motion.cca_jacobian_point
    return run(f, jac_f, x, prior, step_args, q, weights, angles, new_mean, new_cov, s)


@numba.njit
def leading_entries_update_run(
    x, prior, z, step_args, r, weights, state_angles, angles, new_mean, new_cov, s
):
    """:func:`update_run` with the GPS / pose kernels."""
    h, jac_h = motion.leading_entries_point, motion.leading_entries_jacobian_point
    return update_run(
        h, jac_h, x, prior, z, step_args, r, weights, state_angles, angles, new_mean, new_cov, s
    )


_builtin_predict = batched_predict(builtin_predict_run, predict_scratch_length)
_leading_entries_update = batched_update(leading_entries_update_run, update_scratch_length)


@numba.njit(cache=True)
def predict_builtin(model, mean, cov, args, q_cov, weights, angles, out_mean, out_cov):
    """The batched prediction by :func:`builtin_predict_run` (``weights`` unused)."""
    return _builtin_predict(model, mean, cov, args, q_cov, weights, angles, out_mean, out_cov)


@numba.njit(cache=True)
def update_leading_entries(
    mean, cov, z, args, r_cov, weights, state_angles, angles, out_mean, out_cov
):
    """The batched update by :func:`leading_entries_update_run` (the GPS or pose model)."""
    return _leading_entries_update(
        mean, cov, z, args, r_cov, weights, state_angles, angles, out_mean, out_cov
    )


#: Prediction entries by ``(f, F)`` kernels: ``(entry, number)``, called ``entry(number, ...)``;
#: the built-ins' (cached on disk), then users' (:func:`predict_entry`).
PREDICT_ENTRIES = {
    pair: (predict_builtin, number) for number, pair in enumerate(BUILTIN_PROCESS_KERNELS)
}

#: Update entries by ``(h, H)`` kernels: the built-in one (cached on disk), then users'.
UPDATE_ENTRIES = {
    (
        motion.leading_entries_point,
        motion.leading_entries_jacobian_point,
    ): update_leading_entries
}


def predict_entry(point, jacobian_point) -> tuple:
    """``(entry, number)``: the compiled prediction entry of the kernels ``(f, F)`` (built-in:
    cached on disk; a user's: built here once per pair and process, compiled at its first call)."""
    key = (point, jacobian_point)
    found = PREDICT_ENTRIES.get(key)
    if found is None:

        @numba.njit
        def run(selector, x, prior, step_args, q, weights, angles, new_mean, new_cov, s):
            f, jac_f = point, jacobian_point
            return predict_run(
                f, jac_f, x, prior, step_args, q, weights, angles, new_mean, new_cov, s
            )

        entry = batched_predict(run, predict_scratch_length)
        found = PREDICT_ENTRIES[key] = (entry, -1)
    return found


def update_entry(point, jacobian_point):
    """The compiled update entry of the kernels ``(h, H)`` (as :func:`predict_entry`)."""
    key = (point, jacobian_point)
    found = UPDATE_ENTRIES.get(key)
    if found is None:

        @numba.njit
        def run(x, prior, z, step_args, r, weights, state_angles, angles, new_mean, new_cov, s):
            h, jac_h = point, jacobian_point
            return update_run(
                h,
                jac_h,
                x,
                prior,
                z,
                step_args,
                r,
                weights,
                state_angles,
                angles,
                new_mean,
                new_cov,
                s,
            )

        entry = batched_update(run, update_scratch_length)
        found = UPDATE_ENTRIES[key] = entry
    return found


# -------------------------------------------------------------------------- the Python side

#: The sigma weights the EKF entries take and ignore (the arguments they share with the UKF's).
NO_WEIGHTS = read_only(np.zeros(3))


def predict(
    mean: np.ndarray, cov: np.ndarray, angle_indices: tuple[int, ...], model, args: tuple
) -> tuple[np.ndarray, np.ndarray] | None:
    """The compiled prediction ``(mean, cov)`` of a belief, or ``None`` (numpy path).

    ``model`` is an additive-noise :class:`~localization.models.ProcessModel` with both
    kernels. ``None`` when the step is not expressible here
    (:func:`~localization.compiled.glue.entry_arrays`) or failed (status).
    """
    arrays = entry_arrays(mean, cov, model.Q, args)
    if arrays is None:
        return None
    mean_b, cov_b, _, packed, q_cov, outputs = arrays
    key = (model.point, model.jacobian_point)
    entry, number = PREDICT_ENTRIES.get(key) or predict_entry(*key)
    angles = angle_array(angle_indices)
    arguments = (number, mean_b, cov_b, packed, q_cov, NO_WEIGHTS, angles, *outputs)
    return call_entry(entry, arguments, "EKF", "predict", key, mean.ndim == 2)


def update(
    mean: np.ndarray, cov: np.ndarray, angle_indices: tuple[int, ...], z, model, args: tuple
) -> tuple[np.ndarray, np.ndarray] | None:
    """The compiled update ``(mean, cov)`` of a belief by ``z (..., m)``, or ``None`` (numpy path).

    As :func:`predict`; also ``None`` when ``z`` is not a real array of shape ``batch + (m,)``
    (the numpy path then refuses it with its message) or ``S`` is not positive definite.
    """
    arrays = entry_arrays(mean, cov, model.R, args, z)
    if arrays is None:
        return None
    mean_b, cov_b, z_b, packed, r_cov, outputs = arrays
    key = (model.point, model.jacobian_point)
    entry = UPDATE_ENTRIES.get(key) or update_entry(*key)
    arguments = (
        mean_b,
        cov_b,
        z_b,
        packed,
        r_cov,
        NO_WEIGHTS,
        angle_array(angle_indices),
        angle_array(model.angle_indices),
        *outputs,
    )
    return call_entry(entry, arguments, "EKF", "update", key, mean.ndim == 2)
