"""The loop over a batch's runs around a per-run step: the compiled EKF's and a user kernel's UKF.

:mod:`localization.compiled.ukf` and :mod:`localization.compiled.ekf` write each step once for
one run (the built-in UKF kernels' batches take :mod:`localization.compiled.soa` instead),
their run functions taking the same arguments in the same order::

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

The arguments are passed on one by one: a tuple of arrays passed as ``*args`` costs a step
some 200 ns. Factories rather than cores taking ``run`` as an argument: numba does not cache
an entry that passes a function which itself passes a function (the kernel); the entries
Python calls are module-level functions of the filter modules that call what these build.
"""

from __future__ import annotations

import numba
import numpy as np
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic
from numba.np.arrayobj import make_array, populate_array

from localization.compiled.glue import NOT_FINITE, OK
from localization.compiled.linalg import all_finite

# Borrowed views. numba counts the references to an array's memory: every view taken in
# compiled code (a slice, a row, a reshape) increments the owner's count and decrements it when
# dropped, each an atomic operation; a UKF step takes some hundred views (its scratch carved,
# the rows of its sigma points), and the counting was a third of its time (about 1 us of 3,
# session 24). A borrowed view is one without an owner (no meminfo, no parent), so neither it
# nor any view taken from it is counted. It is valid while the array it was taken from lives,
# which the functions using them guarantee: they take views of their arguments or of an array
# they allocated, and return none of them (a borrowed view returned to Python would be an
# array without an owner of its memory).


def _populate_borrowed(context, builder, view, source, shape, strides) -> object:
    """Fill the array struct ``view`` as a view of ``source``'s data without an owner."""
    meminfo_type = source.meminfo.type
    populate_array(
        view,
        data=source.data,
        shape=shape,
        strides=strides,
        itemsize=source.itemsize,
        meminfo=cgutils.get_null_value(meminfo_type),
        parent=cgutils.get_null_value(source.parent.type),
    )
    return view._getvalue()


@intrinsic
def borrow(typingctx, values):
    """``values`` (an array, any shape) as a borrowed view: the same array, not counted."""

    def codegen(context, builder, signature, args):
        source = make_array(signature.args[0])(context, builder, value=args[0])
        view = make_array(signature.return_type)(context, builder)
        return _populate_borrowed(context, builder, view, source, source.shape, source.strides)

    return values(values), codegen


@intrinsic
def _borrowed_matrix(typingctx, vector, rows, cols):
    """``vector (rows * cols,)``, C-contiguous, as a borrowed C-contiguous ``(rows, cols)`` view
    (the caller checks the length): ``vector.reshape((rows, cols))`` without numba's C reshape
    helper (about 40 ns a call) and not counted."""
    result = types.Array(vector.dtype, 2, "C", readonly=not vector.mutable)

    def codegen(context, builder, signature, args):
        vector_type, rows_type, cols_type = signature.args
        source = make_array(vector_type)(context, builder, value=args[0])
        n_rows = context.cast(builder, args[1], rows_type, types.intp)
        n_cols = context.cast(builder, args[2], cols_type, types.intp)
        shape = cgutils.pack_array(builder, [n_rows, n_cols])
        row_stride = builder.mul(n_cols, source.itemsize)
        strides = cgutils.pack_array(builder, [row_stride, source.itemsize])
        view = make_array(result)(context, builder)
        return _populate_borrowed(context, builder, view, source, shape, strides)

    return result(vector, rows, cols), codegen


@numba.njit
def carve(buffer, start, rows, cols):
    """``(buffer[start:end] as (rows, cols), end)``: a borrowed matrix view (above), whose rows
    and row blocks are then views of it (slices), not counted either."""
    end = start + rows * cols
    if rows < 0 or cols < 0 or end > buffer.shape[0]:
        raise ValueError("carve: the buffer is too short")
    return _borrowed_matrix(buffer[start:end], rows, cols), end


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
        work = np.empty(length(mean.shape[1], noise.shape[1]))  # lives through the loop
        mean, cov, args, noise = borrow(mean), borrow(cov), borrow(args), borrow(noise)
        out_mean, out_cov = borrow(out_mean), borrow(out_cov)
        for b in range(mean.shape[0]):
            x, prior, run_args, run_noise = mean[b], cov[b], _row(args, b), _row(noise, b)
            status = run(
                selector,
                x,
                prior,
                run_args,
                run_noise,
                weights,
                angles,
                out_mean[b],
                out_cov[b],
                work,
            )
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
        work = np.empty(length(mean.shape[1], z.shape[1]))  # lives through the loop
        mean, cov, z, args, r_cov = (
            borrow(mean),
            borrow(cov),
            borrow(z),
            borrow(args),
            borrow(r_cov),
        )
        out_mean, out_cov = borrow(out_mean), borrow(out_cov)
        for b in range(mean.shape[0]):
            x, prior, run_args, run_r = mean[b], cov[b], _row(args, b), _row(r_cov, b)
            status = run(
                x,
                prior,
                z[b],
                run_args,
                run_r,
                weights,
                state_angles,
                angles,
                out_mean[b],
                out_cov[b],
                work,
            )
            if status != OK:
                return status
        return OK

    return core
