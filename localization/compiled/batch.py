"""The loop over a batch's runs, one body for the compiled UKF and EKF steps.

:mod:`localization.compiled.ukf` and :mod:`localization.compiled.ekf` write each step once for
one run, their run functions taking the same arguments in the same order::

    predict: run(selector, x (n,), P (n, n), args (k,), noise (q, q), weights (3,), angles,
                 out_mean (n,), out_cov (n, n), scratch)
    update:  run(x (n,), P (n, n), z (m,), args (k,), R (m, m), weights (3,), state_angles,
                 angles, out_mean (n,), out_cov (n, n), scratch)

(``noise`` is ``Q``, or its square root with the UKF's augmented noise; ``weights`` the UKF's
``(gamma, W_i, c0)``, unused by the EKF; ``selector`` a built-in kernel's number; ``scratch``
one float64 array, which the run function carves into its vectors and matrices with
:func:`carve`.) :func:`batched_predict` and :func:`batched_update` generate the compiled loop
of such a run function over the runs of a batch, its scratch (``length(n, q)`` /
``length(n, m)`` floats) allocated once per call; ``args`` and the noise are shared by every run (leading axis 1) or
given per run (leading axis ``B``). Each returns the first status that is not ``OK`` (the
outputs are then partly written and to be discarded).

Factories rather than cores taking ``run`` as an argument: numba does not cache an entry that
passes a function which itself passes a function (the kernel); the entries Python calls are
module-level functions of the filter modules that call what these build.
"""

from __future__ import annotations

import numba
import numpy as np

from localization.compiled.glue import NOT_FINITE, OK
from localization.compiled.linalg import all_finite


@numba.njit
def carve(buffer, start, rows, cols):
    """``(buffer[start:end] as (rows, cols), end)``: one reshape, whose rows and row blocks are
    then views without one (a reshape is a call of numba's C helper, a slice is not)."""
    end = start + rows * cols
    return buffer[start:end].reshape((rows, cols)), end


@numba.njit
def _row(values, b):
    """Row ``b`` of ``values (B or 1, ...)``: its own, or the shared one."""
    return values[b if values.shape[0] > 1 else 0]


def batched_predict(run, length):
    """``core(selector, mean (B, n), cov (B, n, n), args (B or 1, k), noise (B or 1, q, q),
    weights, angles, out_mean (B, n), out_cov (B, n, n)) -> status`` (module docstring)."""

    @numba.njit
    def core(selector, mean, cov, args, noise, weights, angles, out_mean, out_cov) -> int:
        if not all_finite(args):
            return NOT_FINITE
        work = np.empty(length(mean.shape[1], noise.shape[1]))
        for b in range(mean.shape[0]):
            run_args = (mean[b], cov[b], _row(args, b), _row(noise, b), weights, angles)
            status = run(selector, *run_args, out_mean[b], out_cov[b], work)
            if status != OK:
                return status
        return OK

    return core


def batched_update(run, length):
    """``core(mean, cov, z (B, m), args, r_cov (B or 1, m, m), weights, state_angles, angles,
    out_mean, out_cov) -> status``, as :func:`batched_predict`."""

    @numba.njit
    def core(mean, cov, z, args, r_cov, weights, state_angles, angles, out_mean, out_cov) -> int:
        if not all_finite(args):
            return NOT_FINITE
        work = np.empty(length(mean.shape[1], z.shape[1]))
        for b in range(mean.shape[0]):
            run_args = (mean[b], cov[b], z[b], _row(args, b), _row(r_cov, b))
            status = run(*run_args, weights, state_angles, angles, out_mean[b], out_cov[b], work)
            if status != OK:
                return status
        return OK

    return core
