"""The compiled UKF step (numba): one call per predict or update, whatever the batch size.

Why compiled. A numpy UKF step on 5 states is some 75 numpy calls on tiny arrays, each about
1 us of call overhead: about 100 us for one filter, where the arithmetic needs a few hundred
nanoseconds (``benchmarks/ukf_step.py``, ``benchmarks/filters.py``). Here a step is one call
of a compiled entry that loops over the runs and the sigma points in scalar code and calls
the model once per sigma point. :class:`~localization.ukf.UnscentedKalmanFilter` uses it
whenever the model carries a per-point kernel (``point=`` of
:class:`~localization.models.ProcessModel` and :class:`~localization.models.MeasurementModel`)
and the step can be expressed here; otherwise, and whenever a step fails, it runs its numpy
path, which stays the reference (same results to rounding, tested in
``tests/localization/test_compiled_ukf.py``).

The maths is the numpy UKF's, term by term (:mod:`localization.ukf`,
:mod:`localization.sigma_points`). Prediction (paper 001 eq. 25-27)::

    X_0 = x,  X_i = x + gamma L_i,  X_{n+i} = x - gamma L_i      (L L^T = P, i = 1..n)
    Y_i = f(X_i),  D_i = Y_i - Y_0 (angles wrapped),  d = sum_{i>=1} W_i D_i
    x- = Y_0 + d (angles wrapped),  P- = sum_{i>=1} W_i D_i D_i^T + (c0 - 1) d d^T + Q

with ``W_i = 1 / (2 gamma^2)`` and ``c0 = Wc_0 - Wm_0``; the covariance is formed as
``H + H^T`` of the half product ``H``, so it is exactly symmetric. With augmented noise
(paper 001 section III-C-2) the sigma points are those of ``(x, w)`` with covariance
``blockdiag(P, Q)`` (square root ``blockdiag(L, S)``, ``S S^T = Q``), the images
``Y_i = f(X_i^x, X_i^w)`` and no ``+ Q``. Update (paper 001 eq. 29-35)::

    Z_i = h(X_i),  z- = Z_0 + sum W_i (Z_i - Z_0),  S = (moments as above) + R
    Pxz = W_i gamma L (Dz_{1..n} - Dz_{n+1..2n})                   (cross_covariance)
    K^T = S^-1 Pxz^T (Cholesky solve),  x+ = x- + K (z - z-),  P+ = sym(P- - Pxz K^T)

Per-point kernels. A model gives ``f(x (n,), args (k,), out (n,))`` (additive noise),
``f(x (n,), w (q,), args (k,), out (n,))`` (augmented noise) or ``h(x (n,), args (k,), out (m,))``,
compiled with ``numba.njit``, writing its result into ``out``; ``x`` and ``w`` are scratch
copies of the sigma point (a kernel may overwrite them). ``args`` are the step's extra
arguments packed as floats (:func:`~localization.compiled.glue.pack_args`): each argument
flattened, in order. The kernels of the motion models are :mod:`localization.compiled.motion`.

Entries. Each step is written once for one run (:func:`predict_run`,
:func:`augmented_predict_run`, :func:`update_run`), the kernel and the scratch (one float array,
carved by the run) passed in, so that it allocates nothing; the lean entries of
:mod:`localization.compiled.lean` call the run functions on scratch kept in the filter, and
for a user's own kernel :func:`predict_entry` / :func:`update_entry` build a batched entry,
the loop over the runs of :mod:`localization.compiled.batch` around a run function (uncached,
compiled at its first call and memoised per kernel). Functions that take a kernel as an
argument are only called from other compiled functions, so numba inlines the kernel into a
specialised copy. The batched entries of the built-in kernels (:data:`PREDICT_ENTRIES`,
:data:`UPDATE_ENTRIES`) are those of :mod:`localization.compiled.soa`: the same operations
per run as the run functions, a block of runs at a time in structure-of-arrays layout (about
2x faster across runs, bit for bit the same results), cached on disk (``cache=True``); one
prediction entry switches between the four motion models, so their first compilation happens
together. numba's disk cache keys an entry on its own file only;
:mod:`localization.kernel_cache` drops the folder's cache whenever any of its files changes.

Status. An entry returns a status code of :mod:`localization.compiled.glue`: ``OK``,
``NOT_POSITIVE_DEFINITE`` (a covariance to factorise, ``P`` or ``S``) or ``NOT_FINITE`` (an
argument or a result). On anything but ``OK`` the
caller discards the outputs and runs the numpy step, which applies the filter's
:class:`~localization.linalg.PDPolicy` and raises the errors of the numpy path, word for word.

Arrays: float64, C-contiguous; beliefs, noise covariances, weights and packed arguments
read-only, measurements and outputs writable (a fixed set of types per entry, so each compiles once). Runs are
independent and computed by the same code, so a batch gives its runs' one-by-one results bit
for bit.
"""

from __future__ import annotations

import numba
import numpy as np
from numba.extending import register_jitable

from localization.compiled import motion, soa
from localization.compiled.batch import batched_predict, batched_update, carve
from localization.compiled.glue import (
    NOT_FINITE,
    NOT_POSITIVE_DEFINITE,
    OK,
    angle_array,
    call_entry,
    entry_arrays,
)
from localization.compiled.linalg import (
    all_finite,
    cholesky_lower,
    gain_from_cross,
    symmetrise_in_place,
    wrap_angle,
    wrap_residual,
)
from localization.models import ProcessNoise

# ------------------------------------------------------------------------------- the cores


@numba.njit(cache=True)
def _moments(dev, count, y0, weights, angles, noise_cov, out_mean, out_cov, shift) -> None:
    """Mean and covariance of images about the centre one (:func:`localization.sigma_points.unscented_moments`).

    ``dev (>= count, m)`` holds the wrapped deviations ``D_i`` in its first ``count`` rows,
    ``y0 (m,)`` the centre image; ``weights = (gamma, W_i, c0)``; ``noise_cov (m, m)`` is added
    (``Q`` or ``R``), or nothing when it has no rows. Writes ``out_mean (m,)`` (angles wrapped),
    ``out_cov (m, m)`` and ``shift (m,) = d``.
    """
    m = y0.shape[0]
    wi = weights[1]
    half_wi = 0.5 * wi
    half_c = 0.5 * (weights[2] - 1.0)
    for j in range(m):  # d = sum W_i D_i
        total = 0.0
        for row in range(count):
            total += wi * dev[row, j]
        shift[j] = total
        out_mean[j] = y0[j] + total
    for a in angles:
        out_mean[a] = wrap_angle(out_mean[a])
    for j in range(m):  # H = [D; d]^T diag(W_i / 2, (c0 - 1) / 2) [D; d], stored in out_cov
        for k in range(m):
            total = 0.0
            for row in range(count):
                total += (half_wi * dev[row, j]) * dev[row, k]
            out_cov[j, k] = total + (half_c * shift[j]) * shift[k]
    added = noise_cov.shape[0] > 0
    for j in range(m):  # H + H^T (+ noise)
        for k in range(j + 1):
            value = out_cov[j, k] + out_cov[k, j]
            if added:
                value = value + noise_cov[j, k]
            out_cov[j, k] = value
            out_cov[k, j] = value


@numba.njit(cache=True)
def _wrap_row(dev, row, angles) -> None:
    for a in angles:
        dev[row, a] = wrap_residual(dev[row, a])


@numba.njit
def _deviations(f, x, chol, gamma, step_args, angles, point, y0, dev) -> None:
    """Images of the sigma points of ``x (n,)``, ``chol (n, n)`` through ``f(point, args, out)``:
    ``y0`` the centre image, ``dev (2n, m)`` the deviations ``D_i = Y_i - Y_0`` (angles wrapped),
    rows ``0..n-1`` for ``x + gamma L_i`` and ``n..2n-1`` for ``x - gamma L_i``."""
    n = x.shape[0]
    point[:] = x
    f(point, step_args, y0)
    for i in range(n):
        for half in range(2):
            row = i + half * n
            for j in range(n):
                spread = gamma * chol[j, i]
                point[j] = x[j] + spread if half == 0 else x[j] - spread
            f(point, step_args, dev[row])
            for j in range(y0.shape[0]):
                dev[row, j] -= y0[j]
            _wrap_row(dev, row, angles)


# Each step is written once per run (``*_run``: one belief, its scratch passed in as one float
# array that it carves, so that it allocates nothing); the batched cores
# (:mod:`localization.compiled.batch`) loop a run function over the runs with the scratch
# allocated once per call, and the lean entries (:mod:`localization.compiled.lean`) call the
# run functions on scratch kept in the filter. A prediction's run function is called
# ``run(selector, x, P, ...)``: ``selector`` is the built-in kernel's number
# (:data:`BUILTIN_PROCESS_KERNELS`) for the built-in runs, unused for a user's kernel.


@register_jitable
def predict_scratch_length(n, q):
    """The floats of a prediction's scratch (:func:`predict_run`, :func:`augmented_predict_run`)
    of ``n`` states with ``q`` noise inputs (``q = n`` additive)."""
    return (3 + n + 2 * (n + q)) * n + q


@numba.njit
def _predict_views(scratch, n, q):
    """``scratch (predict_scratch_length(n, q),)`` as ``(chol (n, n), point (n,), noise (q,),
    y0 (n,), shift (n,), dev (2 (n + q), n))``."""
    rows, end = carve(scratch, 0, 3 + n + 2 * (n + q), n)
    return rows[:n], rows[n], scratch[end : end + q], rows[n + 1], rows[n + 2], rows[n + 3 :]


@register_jitable
def update_scratch_length(n, m):
    """The floats of the scratch of an update (:func:`update_run`) of ``n`` states by ``m``
    measurements."""
    return (n + 1 + m) * n + (4 + 3 * n + 2 * m) * m


@numba.njit
def predict_run(f, x, prior, step_args, q_cov, weights, angles, out_mean, out_cov, scratch) -> int:
    """Additive-noise prediction of one run (module docstring), ``f(x, args, out)`` per point.

    ``x (n,)``, ``prior (n, n)``, ``step_args (k,)``, ``q_cov (n, n)``, ``weights (3,) =
    (gamma, W_i, c0)``, ``angles`` the state's angle indices (int64), ``scratch``
    ``(predict_scratch_length(n, n),)``; writes ``out_mean (n,)``, ``out_cov (n, n)``. Returns a
    status code.
    """
    chol, point, _, y0, shift, dev = _predict_views(scratch, x.shape[0], x.shape[0])
    if not cholesky_lower(prior, chol):
        return NOT_POSITIVE_DEFINITE
    _deviations(f, x, chol, weights[0], step_args, angles, point, y0, dev)
    _moments(dev, 2 * x.shape[0], y0, weights, angles, q_cov, out_mean, out_cov, shift)
    if not (all_finite(out_mean) and all_finite(out_cov)):
        return NOT_FINITE
    return OK


@numba.njit
def augmented_predict_run(
    f, x, prior, step_args, root, weights, angles, out_mean, out_cov, scratch
) -> int:
    """Augmented-noise prediction of one run, ``f(x, w, args, out)`` per point.

    As :func:`predict_run` with ``root (q, q)`` a square root ``S S^T = Q``
    (:attr:`~localization.models.ProcessModel.noise_sqrt`) and ``weights`` those of dimension
    ``n + q``. The ``2 (n + q)`` sigma points: ``(x +- gamma L_i, 0)`` for the state columns,
    ``(x, +-gamma S_j)`` for the noise columns.
    """
    n, q = x.shape[0], root.shape[0]
    chol, point, noise, y0, shift, dev = _predict_views(scratch, n, q)
    if not cholesky_lower(prior, chol):
        return NOT_POSITIVE_DEFINITE
    gamma = weights[0]
    point[:] = x
    noise[:] = 0.0
    f(point, noise, step_args, y0)
    dim = n + q
    for i in range(dim):
        for half in range(2):
            row = i + half * dim
            for j in range(n):
                spread = gamma * chol[j, i] if i < n else 0.0
                point[j] = x[j] + spread if half == 0 else x[j] - spread
            for j in range(q):
                spread = gamma * root[j, i - n] if i >= n else 0.0
                noise[j] = spread if half == 0 else -spread
            f(point, noise, step_args, dev[row])
            for j in range(n):
                dev[row, j] -= y0[j]
            _wrap_row(dev, row, angles)
    _moments(dev, 2 * dim, y0, weights, angles, root[:0, :0], out_mean, out_cov, shift)
    if not (all_finite(out_mean) and all_finite(out_cov)):
        return NOT_FINITE
    return OK


@numba.njit
def update_run(
    h, x, prior, z, step_args, r_cov, weights, state_angles, angles, out_mean, out_cov, scratch
) -> int:
    """Measurement update of one run (module docstring), ``h(x, args, out)`` per point.

    ``x (n,)``, ``prior (n, n)``, ``z (m,)``, ``step_args (k,)``, ``r_cov (m, m)``,
    ``weights (3,) = (gamma, W_i, c0)``, ``state_angles`` and ``angles`` (the measurement's)
    angle indices (int64), ``scratch (update_scratch_length(n, m),)``; writes ``out_mean (n,)``,
    ``out_cov (n, n)``. Returns a status code.
    """
    n, m = x.shape[0], z.shape[0]
    rows_n, end = carve(scratch, 0, n + 1 + m, n)
    chol, point, gain_t = rows_n[:n], rows_n[n], rows_n[n + 1 :]
    rows_m, _ = carve(scratch, end, 4 + 3 * n + 2 * m, m)
    z0, shift, z_pred, innovation = rows_m[0], rows_m[1], rows_m[2], rows_m[3]
    dev, cross = rows_m[4 : 4 + 2 * n], rows_m[4 + 2 * n : 4 + 3 * n]
    s_cov, s_chol = rows_m[4 + 3 * n : 4 + 3 * n + m], rows_m[4 + 3 * n + m :]
    if not all_finite(z):
        return NOT_FINITE
    if not cholesky_lower(prior, chol):
        return NOT_POSITIVE_DEFINITE
    gamma = weights[0]
    _deviations(h, x, chol, gamma, step_args, angles, point, z0, dev)
    _moments(dev, 2 * n, z0, weights, angles, r_cov, z_pred, s_cov, shift)
    scale = weights[1] * gamma
    for i in range(n):  # Pxz = W_i gamma L (D_{1..n} - D_{n+1..2n})
        for c in range(m):
            total = 0.0
            for k in range(n):
                total += chol[i, k] * (dev[k, c] - dev[n + k, c])
            cross[i, c] = scale * total
    if not gain_from_cross(s_cov, cross, s_chol, gain_t):  # K^T = S^-1 Pxz^T
        return NOT_POSITIVE_DEFINITE
    for c in range(m):
        innovation[c] = z[c] - z_pred[c]
    for a in angles:
        innovation[a] = wrap_angle(innovation[a])
    for i in range(n):  # x+ = x- + K (z - z-)
        total = 0.0
        for c in range(m):
            total += innovation[c] * gain_t[c, i]
        out_mean[i] = x[i] + total
    for a in state_angles:
        out_mean[a] = wrap_angle(out_mean[a])
    for i in range(n):  # P+ = P- - Pxz K^T, symmetrised
        for j in range(n):
            total = 0.0
            for c in range(m):
                total += cross[i, c] * gain_t[c, j]
            out_cov[i, j] = prior[i, j] - total
    symmetrise_in_place(out_cov)
    if not (all_finite(out_mean) and all_finite(out_cov)):
        return NOT_FINITE
    return OK


# ------------------------------------------------------------------- cached built-in entries
# Module-level entries, so numba caches their machine code on disk; one entry holds the
# four motion models (a closure per model would not be cached). The kernel is named as a
# module attribute (``motion.ctrv_point``): numba resolves that to a constant while
# typing, whereas a bare imported name passed as a value is lowered as a pointer to the
# Python object, which makes the entry uncacheable ("dynamic globals"). The entries Python
# calls take no function argument: one that does is compiled again in every process.


#: The built-in process kernels (additive, augmented), by the number the entries switch on.
BUILTIN_PROCESS_KERNELS = (
    (motion.cv_point, motion.cv_noisy_point),
    (motion.ctrv_point, motion.ctrv_noisy_point),
    (motion.ctra_point, motion.ctra_noisy_point),
    (motion.cca_point, motion.cca_noisy_point),
)


# The kernel is named as a module attribute in each call (above): a kernel passed through
# ``*args``, or held in a closure and passed on, would make the entry a first-class function
# call or uncacheable, so the switches spell their calls out.


@numba.njit
def builtin_predict_run(model, x, prior, step_args, q_cov, weights, angles, out_mean, out_cov, s):
    """:func:`predict_run` with the additive kernel number ``model`` of :data:`BUILTIN_PROCESS_KERNELS`."""
    if model == 0:
        f = motion.cv_point
        return predict_run(f, x, prior, step_args, q_cov, weights, angles, out_mean, out_cov, s)
    if model == 1:
        f = motion.ctrv_point
        return predict_run(f, x, prior, step_args, q_cov, weights, angles, out_mean, out_cov, s)
    if model == 2:
        f = motion.ctra_point
        return predict_run(f, x, prior, step_args, q_cov, weights, angles, out_mean, out_cov, s)
    f = motion.cca_point
    return predict_run(f, x, prior, step_args, q_cov, weights, angles, out_mean, out_cov, s)


@numba.njit
def builtin_augmented_predict_run(
    model, x, prior, step_args, root, weights, angles, out_mean, out_cov, s
):
    """:func:`augmented_predict_run` with the kernel number ``model`` of :data:`BUILTIN_PROCESS_KERNELS`."""
    run = augmented_predict_run
    if model == 0:
        f = motion.cv_noisy_point
        return run(f, x, prior, step_args, root, weights, angles, out_mean, out_cov, s)
    if model == 1:
        f = motion.ctrv_noisy_point
        return run(f, x, prior, step_args, root, weights, angles, out_mean, out_cov, s)
    if model == 2:
        f = motion.ctra_noisy_point
        return run(f, x, prior, step_args, root, weights, angles, out_mean, out_cov, s)
    f = motion.cca_noisy_point
    return run(f, x, prior, step_args, root, weights, angles, out_mean, out_cov, s)


@numba.njit
def leading_entries_update_run(
    x, prior, z, step_args, r_cov, weights, state_angles, angles, out_mean, out_cov, s
):
    """:func:`update_run` with the GPS / pose kernel."""
    h = motion.leading_entries_point
    return update_run(
        h, x, prior, z, step_args, r_cov, weights, state_angles, angles, out_mean, out_cov, s
    )


#: Prediction entries by (kernel, augmented): ``(entry, number)``, called ``entry(number, ...)``;
#: the built-ins' (:mod:`localization.compiled.soa`, cached on disk), then users'
#: (:func:`predict_entry`).
PREDICT_ENTRIES = {
    (kernel, bool(augmented)): (
        soa.noisy_predict_builtin if augmented else soa.predict_builtin,
        number,
    )
    for number, pair in enumerate(BUILTIN_PROCESS_KERNELS)
    for augmented, kernel in enumerate(pair)
}

#: Cached entries of the built-in measurement kernels, by kernel.
UPDATE_ENTRIES = {motion.leading_entries_point: soa.update_leading_entries}


# -------------------------------------------------------------------- entries of user kernels


def predict_entry(point, augmented: bool) -> tuple:
    """``(entry, number)``: the compiled prediction entry of the process kernel ``point``, to be
    called ``entry(number, mean, ...)`` (built-in: cached on disk; a user's: built here once
    per kernel and process, compiled at its first call; its number is unused)."""
    key = (point, augmented)
    found = PREDICT_ENTRIES.get(key)
    if found is None:
        one = augmented_predict_run if augmented else predict_run

        @numba.njit
        def run(selector, x, prior, step_args, noise, weights, angles, out_mean, out_cov, s):
            return one(point, x, prior, step_args, noise, weights, angles, out_mean, out_cov, s)

        entry = batched_predict(run, predict_scratch_length)
        found = PREDICT_ENTRIES[key] = (entry, -1)
    return found


def update_entry(point):
    """The compiled update entry of the measurement kernel ``point`` (as :func:`predict_entry`)."""
    found = UPDATE_ENTRIES.get(point)
    if found is None:

        @numba.njit
        def run(x, prior, z, step_args, r_cov, weights, state_angles, angles, mean, cov, s):
            return update_run(
                point, x, prior, z, step_args, r_cov, weights, state_angles, angles, mean, cov, s
            )

        entry = batched_update(run, update_scratch_length)
        found = UPDATE_ENTRIES[point] = entry
    return found


# -------------------------------------------------------------------------- the Python side


def predict(
    weights, mean: np.ndarray, cov: np.ndarray, angle_indices: tuple[int, ...], model, args: tuple
) -> tuple[np.ndarray, np.ndarray] | None:
    """The compiled prediction ``(mean, cov)`` of a belief, or ``None`` (numpy path).

    ``weights`` are the :class:`~localization.sigma_points.SigmaWeights` of the state (or of
    the augmented state); ``model`` a :class:`~localization.models.ProcessModel` with a kernel.
    ``None`` when the step is not expressible here (:func:`~localization.compiled.glue.entry_arrays`)
    or failed (status).
    """
    augmented = model.noise == ProcessNoise.AUGMENTED
    arrays = entry_arrays(mean, cov, model.noise_sqrt if augmented else model.Q, args)
    if arrays is None:
        return None
    mean_b, cov_b, _, packed, noise, outputs = arrays
    entry, number = PREDICT_ENTRIES.get((model.point, augmented)) or predict_entry(
        model.point, augmented
    )
    arguments = (
        number,
        mean_b,
        cov_b,
        packed,
        noise,
        weights.packed,
        angle_array(angle_indices),
        *outputs,
    )
    return call_entry(entry, arguments, "UKF", "predict", model.point, mean.ndim == 2)


def update(
    weights,
    mean: np.ndarray,
    cov: np.ndarray,
    angle_indices: tuple[int, ...],
    z,
    model,
    args: tuple,
) -> tuple[np.ndarray, np.ndarray] | None:
    """The compiled update ``(mean, cov)`` of a belief by ``z (..., m)``, or ``None`` (numpy path).

    As :func:`predict`; also ``None`` when ``z`` is not a real array of shape ``batch + (m,)``
    (the numpy path then refuses it with its message).
    """
    arrays = entry_arrays(mean, cov, model.R, args, z)
    if arrays is None:
        return None
    mean_b, cov_b, z_b, packed, r_cov, outputs = arrays
    entry = UPDATE_ENTRIES.get(model.point) or update_entry(model.point)
    arguments = (
        mean_b,
        cov_b,
        z_b,
        packed,
        r_cov,
        weights.packed,
        angle_array(angle_indices),
        angle_array(model.angle_indices),
        *outputs,
    )
    return call_entry(entry, arguments, "UKF", "update", model.point, mean.ndim == 2)
