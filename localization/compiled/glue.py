"""The Python side shared by the compiled filter steps: status codes, argument packing, entry calls.

Every compiled entry (:mod:`localization.compiled.ukf`, :mod:`localization.compiled.ekf`,
:mod:`localization.compiled.lean`) returns a status code: :data:`OK`,
:data:`NOT_POSITIVE_DEFINITE` (a covariance to factorise, ``P`` or ``S``) or :data:`NOT_FINITE`
(an argument or a result). Its arrays are float64 and C-contiguous (angle indices int64);
beliefs, noise covariances, weights and packed arguments read-only, measurements and outputs
writable: a fixed set of types per entry, so each compiles once. A step's extra arguments
reach a kernel packed as floats (:func:`pack_args`).
"""

from __future__ import annotations

import numba
import numpy as np

from localization.errors import EstimationError

OK = 0
NOT_POSITIVE_DEFINITE = 1
NOT_FINITE = 2
#: A lean step given a ``z`` of another length than its model's ``m``
#: (:mod:`localization.compiled.lean`).
WRONG_SIZE = 3

# A single step's budget is a few microseconds, so the glue below avoids every check it can:
# noise matrices are read-only C-contiguous float arrays by construction (models.py), beliefs
# almost always are, and a step's arguments are usually the same float every step.

_F64 = np.dtype(np.float64)
_ANGLE_ARRAYS: dict[tuple[int, ...], np.ndarray] = {}
_PACKED_FLOATS: dict[tuple[float, ...], np.ndarray] = {}  # recent all-float arguments, packed
_PACKED_FLOATS_MAX = 64


def angle_array(angle_indices: tuple[int, ...]) -> np.ndarray:
    """The angle indices as a read-only int64 array (memoised per tuple)."""
    found = _ANGLE_ARRAYS.get(angle_indices)
    if found is None:
        found = np.array(angle_indices, dtype=np.int64)
        found.flags.writeable = False
        _ANGLE_ARRAYS[angle_indices] = found
    return found


def read_only(values: np.ndarray) -> np.ndarray:
    """``values`` as a read-only C-contiguous float64 array (itself when it already is one)."""
    flags = values.flags
    if flags.writeable or not flags.c_contiguous or values.dtype is not _F64:
        values = np.array(values, dtype=np.float64, order="C")
        values.flags.writeable = False
    return values


def writable(values: np.ndarray) -> np.ndarray:
    """``values`` as a writable C-contiguous float64 array (itself when it already is one): a
    measurement ``z`` is usually a user's writable array, so this spares a copy per step."""
    flags = values.flags
    if not flags.writeable or not flags.c_contiguous or values.dtype is not _F64:
        values = np.array(values, dtype=np.float64, order="C")
    return values


def pack_args(args: tuple, batch: tuple[int, ...]) -> np.ndarray | None:
    """The step's arguments as read-only floats ``(B or 1, k)``, or ``None`` when they cannot be packed.

    Each argument, in order, contributes its entries flattened: a number one column, a
    per-run array (leading axis ``B``, as :func:`localization.ukf.at_sigma_points` decides) its
    entries per run, any other real array its entries shared by every run. Anything else (not
    real numbers) gives ``None``: the numpy path then takes the step. All-float arguments are
    memoised (a filter's ``dt_s`` repeats every step; at most a few dozen are kept).
    """
    try:
        packed = _PACKED_FLOATS.get(args)
    except TypeError:  # an unhashable argument (an array)
        packed = None
    if packed is not None:
        return packed
    if all(type(a) is float for a in args):  # the common case: (dt_s,) or ()
        if len(_PACKED_FLOATS) >= _PACKED_FLOATS_MAX:
            _PACKED_FLOATS.clear()
        packed = _PACKED_FLOATS[args] = np.array([args], dtype=np.float64).reshape(1, len(args))
        packed.flags.writeable = False
        return packed
    runs = batch[0] if batch else 1
    columns, per_run = [], False
    for a in args:
        if isinstance(a, (int, float, np.integer, np.floating)):
            columns.append(np.full((1, 1), float(a)))
        elif isinstance(a, np.ndarray) and a.dtype.kind in "biuf":
            per_run_array = bool(batch) and a.shape[:1] == batch
            columns.append(a.reshape(runs, -1) if per_run_array else a.reshape(1, -1))
            per_run = per_run or per_run_array
        else:
            return None
    rows = runs if per_run else 1
    packed = np.empty((rows, sum(c.shape[1] for c in columns)))
    start = 0
    for c in columns:
        packed[:, start : start + c.shape[1]] = c
        start += c.shape[1]
    packed.flags.writeable = False
    return packed


def per_run(cov: np.ndarray, runs: int) -> np.ndarray | None:
    """A noise matrix ``(k, k)`` or per-run ``(B, k, k)`` as ``(1 or B, k, k)``, or ``None``."""
    if cov.ndim == 2:
        return cov[None]
    if cov.ndim == 3 and cov.shape[0] == runs:
        return cov
    return None


def compile_error(filter_name: str, kind: str, point, exc: Exception) -> EstimationError:
    """The error for a user's kernel (or tuple of kernels, the EKF's model and Jacobian) that
    does not compile for a ``kind`` (``"predict"`` or ``"update"``) step of ``filter_name``."""
    points = point if isinstance(point, tuple) else (point,)
    names = " and ".join(getattr(p, "__name__", repr(p)) for p in points)
    if filter_name == "EKF":
        expected = (
            "h(x, args, out (m,)) and H(x, args, out (m, n))"
            if kind == "update"
            else ("f(x, args, out (n,)) and F(x, args, out (n, n))")
        )
    else:
        expected = (
            "h(x, args, out)" if kind == "update" else "f(x, args, out) or f(x, w, args, out)"
        )
    return EstimationError(
        f"{filter_name} {kind}: the kernel {names} does not compile for this step (expected {expected} "
        f"on float64 arrays): {str(exc).strip().splitlines()[0]}"
    )


def runs_of(mean: np.ndarray) -> int:
    """The number of runs of a belief that the compiled path takes, or 0 (numpy path)."""
    if mean.ndim == 1:
        return 1
    return mean.shape[0] if mean.ndim == 2 else 0


def entry_arrays(mean: np.ndarray, cov: np.ndarray, noise: np.ndarray, args: tuple, z=None):
    """The arrays a compiled predict or update entry takes, or ``None`` when the step cannot be
    expressed there (the numpy path then takes it).

    ``mean (..., n)``, ``cov (..., n, n)`` a belief of one run or a flat batch, ``noise`` a
    noise matrix ``(k, k)`` or per run ``(B, k, k)`` (``Q``, its square root or ``R``),
    ``args`` the step's arguments, ``z`` the measurement of an update (``None`` for a
    prediction): ``None`` too when it is not a real array of shape ``batch + (m,)``, ``m`` that
    of ``noise``. Returns ``(mean (B, n), cov (B, n, n), z (B, m) or None, packed args,
    noise (1 or B, k, k), (out_mean (B, n), out_cov (B, n, n)))``, the inputs read-only (``z``
    writable), the outputs new.
    """
    runs = runs_of(mean)
    noise_b = per_run(noise, runs)
    packed = pack_args(args, mean.shape[:-1])
    if runs == 0 or noise_b is None or packed is None:
        return None
    if z is not None:
        m = noise_b.shape[-1]
        if (
            not isinstance(z, np.ndarray)
            or z.shape != mean.shape[:-1] + (m,)
            or z.dtype.kind not in "biuf"
        ):
            return None
        z = writable(z.reshape(runs, m))
    n = mean.shape[-1]
    return (
        read_only(mean.reshape(runs, n)),
        read_only(cov.reshape(runs, n, n)),
        z,
        packed,
        noise_b,
        (np.empty((runs, n)), np.empty((runs, n, n))),
    )


def call_entry(entry, arguments: tuple, filter_name: str, kind: str, kernels, batched: bool):
    """``entry(*arguments)`` (its last two arguments the outputs ``(B, n)``, ``(B, n, n)``) as a
    step's result: ``(mean, cov)`` (one run's when not ``batched``), or ``None`` when the status
    is not :data:`OK` (the numpy path then takes the step). A user's kernel that does not
    compile raises :func:`compile_error` for ``filter_name``, ``kind`` and ``kernels``."""
    try:
        status = entry(*arguments)
    except numba.core.errors.TypingError as exc:
        raise compile_error(filter_name, kind, kernels, exc) from None
    if status != OK:
        return None
    out_mean, out_cov = arguments[-2], arguments[-1]
    return (out_mean, out_cov) if batched else (out_mean[0], out_cov[0])
