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

Entries. The cores take the kernels as arguments and are called only from other compiled
functions; the entries Python calls are module-level and cached on disk for the built-in
kernels (one prediction entry switches between the four motion models by their number in
:data:`BUILTIN_PROCESS_KERNELS`); a user's own kernels get an uncached entry, built once per
pair of kernels (:func:`predict_entry`, :func:`update_entry`).

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

from localization.compiled import motion
from localization.compiled.glue import (
    NOT_FINITE,
    NOT_POSITIVE_DEFINITE,
    OK,
    angle_array,
    call_entry,
    pack_args,
    per_run,
    read_only,
    runs_of,
    writable,
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
def predict_core(f, jac_f, mean, cov, args, q_cov, angles, out_mean, out_cov) -> int:
    """EKF prediction of every run (module docstring), ``f(x, args, out)``, ``F(x, args, out)``.

    ``mean (B, n)``, ``cov (B, n, n)``, ``args (B or 1, k)``, ``q_cov (B or 1, n, n)``,
    ``angles`` the state's angle indices (int64); writes ``out_mean (B, n)``,
    ``out_cov (B, n, n)``. Returns a status code.
    """
    runs, n = mean.shape
    if not all_finite(args):
        return NOT_FINITE
    point = np.empty(n)
    jac = np.empty((n, n))
    temp = np.empty((n, n))
    for b in range(runs):
        step_args = args[b if args.shape[0] > 1 else 0]
        point[:] = mean[b]
        jac_f(point, step_args, jac)
        point[:] = mean[b]
        new_mean = out_mean[b]
        f(point, step_args, new_mean)
        for a in angles:
            new_mean[a] = wrap_angle(new_mean[a])
        new_cov = out_cov[b]
        _sandwich(jac, cov[b], temp, new_cov)  # (F P) F^T
        q = q_cov[b if q_cov.shape[0] > 1 else 0]
        for i in range(n):
            for j in range(n):
                new_cov[i, j] += q[i, j]
        symmetrise_in_place(new_cov)
        if not (all_finite(new_mean) and all_finite(new_cov)):
            return NOT_FINITE
    return OK


@numba.njit
def update_core(
    h, jac_h, mean, cov, z, args, r_cov, state_angles, angles, out_mean, out_cov
) -> int:
    """EKF update of every run in Joseph form (module docstring), ``h(x, args, out)``, ``H(x, args, out)``.

    ``mean (B, n)``, ``cov (B, n, n)``, ``z (B, m)``, ``args (B or 1, k)``,
    ``r_cov (B or 1, m, m)``, ``state_angles`` and ``angles`` (the measurement's) angle
    indices (int64); writes ``out_mean (B, n)``, ``out_cov (B, n, n)``. Returns a status code.
    """
    runs, n = mean.shape
    m = z.shape[1]
    if not (all_finite(args) and all_finite(z)):
        return NOT_FINITE
    point = np.empty(n)
    z_pred = np.empty(m)
    innovation = np.empty(m)
    jac = np.empty((m, n))
    cross = np.empty((n, m))
    s_cov = np.empty((m, m))
    s_chol = np.empty((m, m))
    gain_t = np.empty((m, n))
    gain = np.empty((n, m))
    joseph = np.empty((n, n))
    temp = np.empty((n, n))
    noise_part = np.empty((n, n))
    temp_noise = np.empty((n, m))
    for b in range(runs):
        step_args = args[b if args.shape[0] > 1 else 0]
        x = mean[b]
        prior = cov[b]
        r = r_cov[b if r_cov.shape[0] > 1 else 0]
        point[:] = x
        h(point, step_args, z_pred)
        for c in range(m):
            innovation[c] = z[b, c] - z_pred[c]
        for a in angles:
            innovation[a] = wrap_angle(innovation[a])
        point[:] = x
        jac_h(point, step_args, jac)
        if not kalman_gain_t(prior, jac, r, cross, s_cov, s_chol, gain_t):  # K^T = S^-1 (P H^T)^T
            return NOT_POSITIVE_DEFINITE
        new_mean = out_mean[b]
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
        new_cov = out_cov[b]
        _sandwich(joseph, prior, temp, new_cov)  # (A P) A^T
        _sandwich(gain, r, temp_noise, noise_part)  # (K R) K^T
        for i in range(n):
            for j in range(n):
                new_cov[i, j] += noise_part[i, j]
        symmetrise_in_place(new_cov)
        if not (all_finite(new_mean) and all_finite(new_cov)):
            return NOT_FINITE
    return OK


# ------------------------------------------------------------------- cached built-in entries
# As in localization.compiled.ukf: module-level entries (cached on disk), kernels named as
# module attributes so that numba resolves them to constants.

#: The built-in process kernels ``(f, F)``, by the number :func:`predict_builtin` switches on.
BUILTIN_PROCESS_KERNELS = (
    (motion.cv_point, motion.cv_jacobian_point),
    (motion.ctrv_point, motion.ctrv_jacobian_point),
    (motion.ctra_point, motion.ctra_jacobian_point),
    (motion.cca_point, motion.cca_jacobian_point),
)


@numba.njit(cache=True)
def predict_builtin(model, mean, cov, args, q_cov, angles, out_mean, out_cov):
    """:func:`predict_core` with the kernels number ``model`` of :data:`BUILTIN_PROCESS_KERNELS`."""
    if model == 0:
        return predict_core(
            motion.cv_point,
            motion.cv_jacobian_point,
            mean,
            cov,
            args,
            q_cov,
            angles,
            out_mean,
            out_cov,
        )
    if model == 1:
        return predict_core(
            motion.ctrv_point,
            motion.ctrv_jacobian_point,
            mean,
            cov,
            args,
            q_cov,
            angles,
            out_mean,
            out_cov,
        )
    if model == 2:
        return predict_core(
            motion.ctra_point,
            motion.ctra_jacobian_point,
            mean,
            cov,
            args,
            q_cov,
            angles,
            out_mean,
            out_cov,
        )
    return predict_core(
        motion.cca_point,
        motion.cca_jacobian_point,
        mean,
        cov,
        args,
        q_cov,
        angles,
        out_mean,
        out_cov,
    )


@numba.njit(cache=True)
def update_leading_entries(mean, cov, z, args, r_cov, state_angles, angles, out_mean, out_cov):
    return update_core(
        motion.leading_entries_point,
        motion.leading_entries_jacobian_point,
        mean,
        cov,
        z,
        args,
        r_cov,
        state_angles,
        angles,
        out_mean,
        out_cov,
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
        def entry(model, mean, cov, args, q_cov, angles, out_mean, out_cov):
            return predict_core(
                point, jacobian_point, mean, cov, args, q_cov, angles, out_mean, out_cov
            )

        found = PREDICT_ENTRIES[key] = (entry, -1)
    return found


def update_entry(point, jacobian_point):
    """The compiled update entry of the kernels ``(h, H)`` (as :func:`predict_entry`)."""
    key = (point, jacobian_point)
    found = UPDATE_ENTRIES.get(key)
    if found is None:

        @numba.njit
        def entry(mean, cov, z, args, r_cov, state_angles, angles, out_mean, out_cov):
            return update_core(
                point,
                jacobian_point,
                mean,
                cov,
                z,
                args,
                r_cov,
                state_angles,
                angles,
                out_mean,
                out_cov,
            )

        found = UPDATE_ENTRIES[key] = entry
    return found


# -------------------------------------------------------------------------- the Python side


def predict(
    mean: np.ndarray, cov: np.ndarray, angle_indices: tuple[int, ...], model, args: tuple
) -> tuple[np.ndarray, np.ndarray] | None:
    """The compiled prediction ``(mean, cov)`` of a belief, or ``None`` (numpy path).

    ``model`` is an additive-noise :class:`~localization.models.ProcessModel` with both
    kernels. ``None`` when the step is not expressible here (a batch of more than one axis or
    empty, arguments that are not numbers, a ``Q`` of another batch) or failed (status).
    """
    runs = runs_of(mean)
    q_cov = per_run(model.Q, runs)
    packed = pack_args(args, mean.shape[:-1])
    if runs == 0 or q_cov is None or packed is None:
        return None
    n = mean.shape[-1]
    out_mean, out_cov = np.empty((runs, n)), np.empty((runs, n, n))
    key = (model.point, model.jacobian_point)
    entry, number = PREDICT_ENTRIES.get(key) or predict_entry(*key)
    arguments = (
        number,
        read_only(mean.reshape(runs, n)),
        read_only(cov.reshape(runs, n, n)),
        packed,
        q_cov,
        angle_array(angle_indices),
        out_mean,
        out_cov,
    )
    return call_entry(entry, arguments, "EKF", "predict", key, mean.ndim == 2)


def update(
    mean: np.ndarray, cov: np.ndarray, angle_indices: tuple[int, ...], z, model, args: tuple
) -> tuple[np.ndarray, np.ndarray] | None:
    """The compiled update ``(mean, cov)`` of a belief by ``z (..., m)``, or ``None`` (numpy path).

    As :func:`predict`; also ``None`` when ``z`` is not a real array of shape ``batch + (m,)``
    (the numpy path then refuses it with its message) or ``S`` is not positive definite.
    """
    runs = runs_of(mean)
    r_cov = per_run(model.R, runs)
    packed = pack_args(args, mean.shape[:-1])
    m = model.R.shape[-1]
    if (
        runs == 0
        or r_cov is None
        or packed is None
        or not isinstance(z, np.ndarray)
        or z.shape != mean.shape[:-1] + (m,)
        or z.dtype.kind not in "biuf"
    ):
        return None
    n = mean.shape[-1]
    out_mean, out_cov = np.empty((runs, n)), np.empty((runs, n, n))
    key = (model.point, model.jacobian_point)
    entry = UPDATE_ENTRIES.get(key) or update_entry(*key)
    arguments = (
        read_only(mean.reshape(runs, n)),
        read_only(cov.reshape(runs, n, n)),
        writable(z.reshape(runs, m)),
        packed,
        r_cov,
        angle_array(angle_indices),
        angle_array(model.angle_indices),
        out_mean,
        out_cov,
    )
    return call_entry(entry, arguments, "EKF", "update", key, mean.ndim == 2)
