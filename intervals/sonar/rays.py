r"""Ray tests of the sonar cone model on pose boxes: the heading kept as one variable.

Why. :mod:`intervals.sonar.cone` bounds the sensor position ``s(p)`` by a box that ranges
independently of the cone direction, and its free-space test needs a direction that is in
the cone for every heading of the box. For a thin cone (half-aperture ``gamma`` below the
heading width of the box) the first is loose and the second never fires. Here every point of
the cone is written as one ray, ``P = s(p) + r u(theta + alpha + delta)`` with ``delta`` in
``[-gamma, gamma]``, and the ray's meeting with each segment is written so that the heading
``theta`` occurs once (exact up to rounding for a ray, ``gamma = 0``).

Notation (metres, radians). Pose ``p = (x, y, theta)``; sensor ``i`` at ``m_i = rho_i (cos
beta_i, sin beta_i)`` in the robot frame, axis ``alpha_i``; ``u(phi) = (cos phi, sin phi)``;
``det(v, w) = v_x w_y - v_y w_x``. World sensor position ``s = (x, y) + rho u(theta + beta)``,
ray direction ``u(phi)``, ``phi = theta + alpha + delta``. Segment ``j``: ``a + t e``,
``t in [0, 1]``, ``e = b - a = L u(epsilon)``. Where the ray meets the segment's line
(``det(u, e) != 0``; the expressions of codac's function in ``benchmarks/intervals_vs_codac.py``)

    lambda = det(a - s, e) / det(u, e)     (distance along the ray: ``u`` is a unit vector)
    t      = det(a - s, u) / det(u, e)     (position along the segment)

With ``B = epsilon - phi`` and ``kappa = alpha + delta - beta`` (``= phi - theta - beta``, free
of ``theta``), angle addition gives ``det(u, e) = L sin B``, ``det(rho u(theta + beta), e) =
rho L sin(B + kappa)`` and ``det(w, u) = cos B det(w, e) / L - sin B (w . e) / L`` for
``w = a - (x, y)``, hence

    lambda = h / sin B - rho cos kappa - rho sin kappa cot B,                   (1)
    t L    = h cot B - (w . e) / L - rho sin kappa / sin B,                     (2)
    h      = g / L = (det(a, e) - x e_y + y e_x) / L = lambda sin B + rho sin(B + kappa).  (3)

``h`` (the signed distance from ``(x, y)`` to the segment's line) and ``(w . e) / L`` are
affine in ``x, y``; the heading enters through ``B`` only. For a ray ``delta = 0``, and for the
radial mounts of the default belt ``kappa = delta``, so the ``kappa`` terms vanish.

Enclosures over a box (or a piece of one, below):

* ``h`` and ``(w . e) / L``: ``x`` and ``y`` occur once each: exact up to rounding.
* ``sin B``, ``1 / sin B``, ``cot B`` (``sine_terms``): from ``sin`` and ``cos`` at the two
  float ends of the ``B`` interval. If both sines have one strict sign and the interval is
  narrower than ``MAX_B_WIDTH_RAD = 3 < pi``, ``sin`` has no zero inside (zeros are ``pi``
  apart, so one zero inside would flip the sign); likewise, if both cosines have one strict
  sign, ``|sin|`` is monotone on it and its range is spanned by the ends (else its maximum is
  1). ``cot`` is decreasing wherever ``sin`` keeps its sign: range ``[cot B_hi, cot B_lo]``.
  Where ``sin B`` may vanish (the ray may run along the line), eq. (1) and (2) claim nothing.
* (1): ``h`` and ``B`` once each in the main term: exact up to rounding for a ray.
* (2): natural evaluation; exact when the segment is parallel to an axis (``h`` then depends
  on one coordinate, ``w . e`` on the other, ``cot B`` occurs once). For a slanted segment
  ``h cot B - (w . e) / L`` is affine in ``cot B`` for fixed ``(x, y)`` and affine in ``(x,
  y)`` (each once) for fixed ``cot B``, so its exact range is the hull of those at the two
  ends of the ``cot`` range (``affine_range``).
* Contraction (hit test only): by (3), the poses whose ``lambda`` lies in the reading's
  ``[lo, hi]`` have ``h`` in ``sin B ([lo, hi] + rho cos kappa + rho sin kappa cot B)``;
  (2) is re-evaluated with ``h`` narrowed to that and intersected with the first enclosure
  (both hold ``t L`` of every such pose). An empty narrowed ``h`` proves that no pose
  has ``lambda`` in ``[lo, hi]``.
* Off-line bound (hit test, where ``sin B`` may vanish): by (3), ``|lambda| |sin B| >= |h| -
  rho``, so if ``min |h| - rho > (hi + GUARD_M) max |sin B|`` the ray cannot meet the line
  within ``hi`` (a wall far off a ray nearly parallel to it).
* Far segment (hit test): a cone point ``P`` at distance at most ``hi`` from the sensor is
  within ``hi + rho`` of ``(x, y)``, so a segment whose bounding box is farther than that from
  the ``(x, y)`` rectangle along ``x`` or ``y`` misses.
* Pieces: each box is cut into ``pieces = (px, py, pt)`` equal sub-boxes (:func:`sub_boxes`;
  neighbours share their float ends, so they cover the box), each tested alone; this restores
  part of the coupling between (1) and (2), which share ``x, y`` and ``B``.

Tests, for sensor ``i`` with the distance interval ``[lo, hi]`` of its reading
(:func:`intervals.sonar.scan.reading_intervals`, outward rounded), on a piece:

* **Hit test** (an echo: ``hi`` finite). If ``d_i(p) in [lo, hi]`` for a pose ``p`` of the
  piece, the nearest cone point ``P`` lies on some segment ``j`` at distance ``d_i(p)`` in a
  direction ``phi = theta + alpha + delta`` of the cone; for that ``p, delta`` the ray meets
  segment ``j`` at ``lambda = d_i(p)`` and ``t in [0, 1]``. With ``delta`` ranging over
  ``[-gamma, gamma]`` the enclosures of (1) and (2) over the piece (the latter narrowed by (3))
  then meet ``[lo, hi]`` and ``[0, L]``, and the off-line bound does not fire. The piece is
  rejected by the sensor when every segment fails one of these. Sound for every ``gamma``:
  only points of the cone are used, and a ray along the line is never excluded.
* **Free-space test** (an echo, or a no-echo reading proving ``d > d_max``: ``lo = d_max``).
  Fix an offset ``delta`` in ``[-gamma, gamma]`` (:data:`FREE_RAY_OFFSETS`). If for every pose
  of the piece that ray surely meets segment ``j`` (``sin B`` one-signed, ``t L`` in ``[0,
  L]``, ``0 <= lambda`` and ``lambda < lo - GUARD_M``), the meeting point is a map point in
  the cone nearer than ``lo``, so ``d_i(p) < lo``: the piece is rejected by the sensor.
* An empty reading interval (``lo > hi``: no fault-free reading gives it) rejects every piece,
  as in :mod:`intervals.sonar.cone`; ignored sensors never reject.

A box is rejected by sensor ``i`` (:func:`ray_rejections`) when every piece is; jointly
(:func:`joint_rejections`) when in every piece more than ``q`` sensors reject the piece (a
pose of the box lies in some piece, where more than ``q`` readings cannot be explained).

Implementation: the compiled kernel (numba) evaluates all of the above triple by triple; its
reference, :mod:`intervals.sonar.reference.rays` (outside the production path, tested against
it), does on arrays of (piece, sensor, segment) triples, with the names used above
(``sine_terms``, ``affine_range``, ``ray_meeting``). The kernel performs the same operations in
the same order and stops early: a sensor's piece is decided once one
segment passes the hit test and one surely meets a free-space ray, and it skips the
evaluation of a segment whose verdict is already known from the off-line and far-segment
bounds (``min |h| - rho >= lo`` also rules out a free-space meeting nearer than ``lo``;
``|sin B| <= 1 + 1e-9``). Both give the same verdicts (tested).

Floating point. Inputs are floats taken as exact reals: box bounds, segment ends, mounts,
reading bounds. The constants (``e``, ``L``, ``epsilon = atan2(e)``, ``rho``, ``beta``,
``kappa`` terms, ``epsilon - alpha - delta``), ``B`` and ``h``, ``(w . e) / L`` are intervals
from :mod:`intervals.interval` (outward rounding; libm sin, cos, atan2 widened by four times
their documented error; angles enclosed modulo ``2 pi``, which sin, cos and cot ignore). The
per-triple arithmetic (``_k_mul``, ``_k_add``, ``_k_sub``, quotients, box gaps) rounds each bound
one ulp outward with ``nextafter``, which encloses the exact result of a correctly rounded
IEEE operation. ``sin``/``cos`` at the ends of ``B`` (numpy's or numba's, whose documented or
measured errors are a few ulps) are enclosed by ``+- TRIG_TOL = 2e-15``: at least 9 ulps of
a value in ``[-1, 1]`` (an ulp there is at most ``2^-52 = 2.2e-16``), which also covers the
rounding of that addition; the sign decisions demand a margin of ``TRIG_TOL``. Every
comparison is moreover biased toward keeping the box by :data:`intervals.sonar.geometry.GUARD_M` (as
in :mod:`intervals.sonar.cone`): a miss needs ``lambda`` outside ``[lo - GUARD_M, hi + GUARD_M]``,
``t L`` outside ``[-GUARD_M, L + GUARD_M]`` or a far segment beyond ``hi + GUARD_M + rho``,
a sure meeting ``lambda < lo - GUARD_M``. A NaN bound (unbounded inputs) fails every strict
comparison and so keeps the box; unbounded intervals are not cut into pieces.
"""

from __future__ import annotations

import functools

import numba
import numpy as np

from intervals import interval as ia
from intervals.boxes import as_boxes
from intervals.errors import IntervalError
from intervals.sonar.geometry import GUARD_M
from intervals.sonar.scan import ECHO, SonarScan

DEFAULT_PIECES = (1, 1, 4)
"""Pieces ``(px, py, pt)`` along x, y and theta into which each box is cut (see the module
doc and :func:`sub_boxes`). Four heading pieces (with :func:`joint_rejections`): in the ray
cases of ``benchmarks/intervals_vs_codac.py`` they take the global set from 3 boxes to
codac's 2 and shrink 4 of the 8 tracking sets, against one piece. Cutting x and y as well,
``(2, 2, 4)``, rejected somewhat more on the real belt (median volume 0.74 of the sonar
test's against 0.81, in our runs) for about 2.5 times the time."""

FREE_RAY_OFFSETS = (-1.0, 1.0)
"""Direction offsets of the free-space rays, as fractions of the half-aperture ``gamma``
(``0``: the cone axis; ``-1, 1``: its edges). The edges: on the real belt (12.5 deg) they
reject boxes the axis does not (in our tracking runs, median outer volume 0.81 of the sonar
test's alone with the edges, 1.00 with the axis alone); adding the axis or half-edges gained
little. On thin cones the edges and the axis are the same ray."""

TRIG_TOL = 2e-15
"""Half-width of the enclosure of a computed ``sin``/``cos`` value in ``[-1, 1]`` (see the
module doc: at least 9 ulps there; it also covers the rounding of ``+- TRIG_TOL``)."""

MAX_B_WIDTH_RAD = 3.0
"""Widest ``B`` interval on which ``sin B`` is claimed to keep one sign (below pi)."""

BLOCK_ELEMENTS = 1 << 18
"""Largest number of (piece, segment) pairs whose terms the kernel is given at once, and of
(piece, sensor, segment) triples in one pass of the numpy reference."""


def _point(values) -> np.ndarray:
    return ia.interval(np.asarray(values, dtype=np.float64))


def _segment_terms(segments: np.ndarray) -> dict[str, np.ndarray]:
    """Per segment ``(m, 2)`` intervals: ``ex, ey, L, epsilon, det(a, e), a . e``."""
    ax, ay = _point(segments[:, 0, 0]), _point(segments[:, 0, 1])
    ex = ia.sub(_point(segments[:, 1, 0]), ax)
    ey = ia.sub(_point(segments[:, 1, 1]), ay)
    return {
        "ex": ex,
        "ey": ey,
        "L": ia.sqrt(ia.add(ia.sqr(ex), ia.sqr(ey))),
        "eps": ia.atan2(ey, ex),
        "det_ae": ia.sub(ia.mul(ax, ey), ia.mul(ay, ex)),
        "dot_ae": ia.add(ia.mul(ax, ex), ia.mul(ay, ey)),
    }


def pose_terms(x, y, seg):
    """``(g / L, (w . e) / L)`` intervals ``(P, 1, m, 2)`` for ``x, y (P, 1, 1, 2)``:
    ``g = det(a, e) - x e_y + y e_x``, ``w . e = a . e - x e_x - y e_y``, x and y once each."""
    g = ia.add(ia.sub(seg["det_ae"], ia.mul(x, seg["ey"])), ia.mul(y, seg["ex"]))
    we = ia.sub(ia.sub(seg["dot_ae"], ia.mul(x, seg["ex"])), ia.mul(y, seg["ey"]))
    return ia.div(g, seg["L"]), ia.div(we, seg["L"])


def _axis_pieces(lo: np.ndarray, hi: np.ndarray, count: int) -> np.ndarray:
    """Pieces ``(N, count, 2)`` of the intervals ``[lo, hi]`` ``(N,)``: neighbours share their
    float ends and the ends are ``lo`` and ``hi``, so the pieces cover the interval (an
    unbounded interval is not cut: each piece is the whole of it)."""
    bounded = np.isfinite(hi - lo)
    width = np.where(bounded, hi - lo, 0.0)
    ends = lo[:, None] + width[:, None] * (np.arange(count + 1) / count)
    ends[:, 0], ends[:, -1] = lo, hi
    ends = np.minimum(np.maximum.accumulate(ends, axis=1), hi[:, None])
    pieces = np.stack([ends[:, :-1], ends[:, 1:]], axis=-1)
    return np.where(bounded[:, None, None], pieces, np.stack([lo, hi], axis=-1)[:, None, :])


def sub_boxes(boxes: np.ndarray, pieces: tuple[int, int, int]) -> np.ndarray:
    """Sub-boxes ``(N, px * py * pt, 3, 2)`` of pose boxes ``(N, 3, 2)`` cut into ``pieces =
    (px, py, pt)`` equal pieces along x, y and theta (x slowest, theta fastest); their union
    is the box (shared float ends)."""
    n = boxes.shape[0]
    axes = [_axis_pieces(boxes[:, d, 0], boxes[:, d, 1], c) for d, c in enumerate(pieces)]
    px, py, pt = pieces
    out = np.empty((n, px, py, pt, 3, 2))
    out[:, :, :, :, 0] = axes[0][:, :, None, None]
    out[:, :, :, :, 1] = axes[1][:, None, :, None]
    out[:, :, :, :, 2] = axes[2][:, None, None, :]
    return out.reshape(n, px * py * pt, 3, 2)


# ---------------------------------------------------------------------------------------------
# The kernel: the operations of the numpy reference (intervals.sonar.reference.rays), per
# (piece, sensor, segment) in scalar loops, with early exits (a sensor's piece is decided as
# soon as one segment is possible for the hit test and one sure for the free-space test).


@numba.njit(cache=True)
def _k_mul(a_lo, a_hi, b_lo, b_hi):
    p0, p1, p2, p3 = a_lo * b_lo, a_lo * b_hi, a_hi * b_lo, a_hi * b_hi
    return (
        np.nextafter(np.minimum(np.minimum(p0, p1), np.minimum(p2, p3)), -np.inf),
        np.nextafter(np.maximum(np.maximum(p0, p1), np.maximum(p2, p3)), np.inf),
    )


@numba.njit(cache=True)
def _k_add(a_lo, a_hi, b_lo, b_hi):
    return np.nextafter(a_lo + b_lo, -np.inf), np.nextafter(a_hi + b_hi, np.inf)


@numba.njit(cache=True)
def _k_sub(a_lo, a_hi, b_lo, b_hi):
    return np.nextafter(a_lo - b_hi, -np.inf), np.nextafter(a_hi - b_lo, np.inf)


@numba.njit(cache=True)
def _k_quotient(c_lo, c_hi, s_lo, s_hi):
    low = c_lo / (s_hi if c_lo >= 0.0 else s_lo)
    high = c_hi / (s_lo if c_hi >= 0.0 else s_hi)
    return np.nextafter(low, -np.inf), np.nextafter(high, np.inf)


@numba.njit(cache=True)
def _k_sine(b_lo, b_hi, out):
    """``sine_terms`` of the numpy reference (:mod:`intervals.sonar.reference.rays`) for one
    interval, into ``out (8,)``: one_sign, inv, cot, sin, big (see the module doc)."""
    tol = TRIG_TOL
    cl, sl, ch, sh = np.cos(b_lo), np.sin(b_lo), np.cos(b_hi), np.sin(b_hi)
    narrow = b_hi - b_lo < MAX_B_WIDTH_RAD
    pos = narrow and sl > tol and sh > tol
    neg = narrow and sl < -tol and sh < -tol
    one_sign = pos or neg
    sign = -1.0 if neg else 1.0
    al, ah, gl, gh = sign * sl, sign * sh, sign * cl, sign * ch
    monotone = (cl > tol and ch > tol) or (cl < -tol and ch < -tol)
    small = np.minimum(al, ah) - tol if one_sign else 1.0
    big = np.maximum(np.abs(sl), np.abs(sh)) + tol if (monotone and narrow) else 1.0
    out[:] = 0.0
    out[7] = big
    if not one_sign:
        return False
    inv_lo, inv_hi = np.nextafter(1.0 / big, -np.inf), np.nextafter(1.0 / small, np.inf)
    out[0], out[1] = (inv_lo, inv_hi) if pos else (-inv_hi, -inv_lo)
    out[2] = _k_quotient(gh - tol, gh + tol, ah - tol, ah + tol)[0]
    out[3] = _k_quotient(gl - tol, gl + tol, al - tol, al + tol)[1]
    out[4], out[5] = (small, big) if pos else (-big, -small)
    return True


@numba.njit(cache=True)
def _k_affine_at(c, x_lo, x_hi, y_lo, y_hi, sv):
    """One end of the reference's ``affine_range``; ``sv (5, 2)``: ex, ey, L, det_ae, dot_ae."""
    coef_x = _k_sub(sv[0, 0], sv[0, 1], *_k_mul(c, c, sv[1, 0], sv[1, 1]))
    coef_y = _k_add(sv[1, 0], sv[1, 1], *_k_mul(c, c, sv[0, 0], sv[0, 1]))
    const = _k_sub(*_k_mul(c, c, sv[3, 0], sv[3, 1]), sv[4, 0], sv[4, 1])
    value = _k_add(*const, *_k_mul(x_lo, x_hi, *coef_x))
    value = _k_add(*value, *_k_mul(y_lo, y_hi, *coef_y))
    return _k_quotient(value[0], value[1], sv[2, 0], sv[2, 1])


@numba.njit(cache=True)
def _k_meeting(b_lo, b_hi, rc, rs, h, we, x, y, sv, slanted, r_lo, r_hi, narrow_t, trig, out):
    """The reference's ``ray_meeting`` for one triple into ``out (4,)``: lambda and t L; returns
    ``(one_sign, sin_max)``. ``narrow_t``: apply the contraction with ``[r_lo, r_hi]``."""
    one_sign = _k_sine(b_lo, b_hi, trig)
    inv, cot, sin = (trig[0], trig[1]), (trig[2], trig[3]), (trig[4], trig[5])
    rs_cot, rs_inv = _k_mul(rs[0], rs[1], *cot), _k_mul(rs[0], rs[1], *inv)
    lam = _k_sub(*_k_sub(*_k_mul(h[0], h[1], *inv), rc[0], rc[1]), *rs_cot)
    if slanted:
        low = _k_affine_at(cot[0], x[0], x[1], y[0], y[1], sv)
        high = _k_affine_at(cot[1], x[0], x[1], y[0], y[1], sv)
        t_len = (np.minimum(low[0], high[0]), np.maximum(low[1], high[1]))
    else:
        t_len = _k_sub(*_k_mul(*cot, h[0], h[1]), we[0], we[1])
    t_len = _k_sub(*t_len, *rs_inv)
    if narrow_t:
        hh = _k_mul(*_k_add(*_k_add(r_lo, r_hi, rc[0], rc[1]), *rs_cot), *sin)
        hh = (np.maximum(h[0], hh[0]), np.minimum(h[1], hh[1]))
        narrowed = _k_sub(*_k_sub(*_k_mul(*cot, *hh), we[0], we[1]), *rs_inv)
        if hh[0] > hh[1]:
            t_len = (np.inf, -np.inf)
        else:
            t_len = (np.maximum(t_len[0], narrowed[0]), np.minimum(t_len[1], narrowed[1]))
    if one_sign:
        out[0], out[1], out[2], out[3] = lam[0], lam[1], t_len[0], t_len[1]
    else:
        out[0], out[1], out[2], out[3] = -np.inf, np.inf, -np.inf, np.inf
    return one_sign, trig[7]


@numba.njit(cache=True)
def _k_piece_rejections(
    parts, pose, seg, bbox, slanted, base, kappa, lo_d, hi_d, kind, rho_hi, guard, out
):
    """Compiled :func:`piece_rejections` on ``parts (P, 3, 2)`` into ``out (P, k)`` bool.

    ``pose (P, m, 2, 2)``: h and (w . e) / L; ``seg (m, 5, 2)``: ex, ey, L, det_ae, dot_ae;
    ``bbox (m, 4)``: the segments' bounding boxes;
    ``slanted (m,)`` bool; ``base (D, k, m, 2)``: epsilon - alpha - delta for the hit ray
    (``D = 0``) and the free-space rays; ``kappa (D, k, 2, 2)``: rho cos kappa, rho sin kappa;
    ``kind (k,)`` int8 of :mod:`intervals.sonar.scan`."""
    n_parts, n_rays, k, m = parts.shape[0], base.shape[0], base.shape[1], base.shape[2]
    trig = np.empty(8)
    res = np.empty(4)
    for p in range(n_parts):
        x, y = (parts[p, 0, 0], parts[p, 0, 1]), (parts[p, 1, 0], parts[p, 1, 1])
        th_lo, th_hi = parts[p, 2, 0], parts[p, 2, 1]
        for i in range(k):
            echo, free = kind[i] == 1, kind[i] == 2
            out[p, i] = False
            if not (echo or free):
                continue
            lo, hi = lo_d[i], hi_d[i]
            if echo and lo > hi:
                out[p, i] = True
                continue
            possible, nearer = not echo, False
            far_hit = np.nextafter(np.nextafter(hi + guard, np.inf) * (1.0 + 1e-9), np.inf)
            far_box = np.nextafter(np.nextafter(hi + guard, np.inf) + rho_hi[i], np.inf)
            for j in range(m):
                h, we = (pose[p, j, 0, 0], pose[p, j, 0, 1]), (pose[p, j, 1, 0], pose[p, j, 1, 1])
                sv = seg[j]
                # shortcut, same verdicts: |lambda| >= min |h| - rho (|sin B| <= 1 + 1e-9)
                off_line = np.nextafter(np.maximum(h[0], -h[1]) - rho_hi[i], -np.inf)
                gap = np.maximum(
                    np.maximum(
                        np.nextafter(bbox[j, 0] - x[1], -np.inf),
                        np.nextafter(x[0] - bbox[j, 1], -np.inf),
                    ),
                    np.maximum(
                        np.nextafter(bbox[j, 2] - y[1], -np.inf),
                        np.nextafter(y[0] - bbox[j, 3], -np.inf),
                    ),
                )
                if not possible and not off_line > far_hit and not gap > far_box:
                    b = _k_sub(base[0, i, j, 0], base[0, i, j, 1], th_lo, th_hi)
                    one_sign, sin_max = _k_meeting(
                        b[0],
                        b[1],
                        (kappa[0, i, 0, 0], kappa[0, i, 0, 1]),
                        (kappa[0, i, 1, 0], kappa[0, i, 1, 1]),
                        h,
                        we,
                        x,
                        y,
                        sv,
                        slanted[j],
                        lo - guard,
                        hi + guard,
                        True,
                        trig,
                        res,
                    )
                    misses = (
                        res[1] < lo - guard
                        or res[0] > hi + guard
                        or res[3] < -guard
                        or res[2] > sv[2, 1] + guard
                        or off_line
                        > np.nextafter(np.nextafter(hi + guard, np.inf) * sin_max, np.inf)
                    )
                    possible = not misses
                for d in range(1, n_rays):
                    # shortcuts, same verdicts: no ray meets the line, or the segment, nearer
                    if nearer or off_line >= lo or gap >= lo + rho_hi[i]:
                        break
                    b = _k_sub(base[d, i, j, 0], base[d, i, j, 1], th_lo, th_hi)
                    one_sign, _ = _k_meeting(
                        b[0],
                        b[1],
                        (kappa[d, i, 0, 0], kappa[d, i, 0, 1]),
                        (kappa[d, i, 1, 0], kappa[d, i, 1, 1]),
                        h,
                        we,
                        x,
                        y,
                        sv,
                        slanted[j],
                        0.0,
                        0.0,
                        False,
                        trig,
                        res,
                    )
                    nearer = (
                        one_sign
                        and res[0] >= 0.0
                        and res[1] < lo - guard
                        and res[2] >= 0.0
                        and res[3] <= sv[2, 0]
                    )
                if possible and nearer:
                    break
            out[p, i] = (echo and not possible) or nearer


def _checked(boxes, scan, pieces) -> tuple[np.ndarray, tuple[int, int, int]]:
    if not isinstance(scan, SonarScan):
        raise IntervalError(
            f"ray test: expected an intervals.sonar.scan.SonarScan, got {type(scan).__name__}"
        )
    if not (len(pieces) == 3 and all(isinstance(c, (int, np.integer)) and c >= 1 for c in pieces)):
        raise IntervalError(f"ray test: pieces must be three integers >= 1, got {pieces!r}")
    boxes = as_boxes(boxes, "ray test boxes")
    if boxes.shape[1] != 3:
        raise IntervalError(f"ray test: pose boxes must be (N, 3, 2), got {boxes.shape}")
    return boxes, (int(pieces[0]), int(pieces[1]), int(pieces[2]))


def _ray_constants(scan) -> dict:
    """:func:`_compute_ray_constants` of the scan's segments and belt (cached: they do not
    depend on the readings, and consecutive scans mostly share them)."""
    seg = np.ascontiguousarray(scan.segments, dtype=np.float64)
    return _cached_constants(scan.belt, seg.tobytes(), seg.shape[0], FREE_RAY_OFFSETS)


@functools.lru_cache(maxsize=64)
def _cached_constants(belt, segment_bytes: bytes, count: int, offsets: tuple) -> dict:
    segments = np.frombuffer(segment_bytes, dtype=np.float64).reshape(count, 2, 2)
    return _compute_ray_constants(segments, belt, offsets)


def _compute_ray_constants(segments, belt, offsets) -> dict:
    """Box-independent intervals of segments ``(m, 2, 2)`` and a belt: segment terms ``(1, 1,
    m, 2)``, per ray (the hit ray over the cone, then the free-space rays at ``offsets``)
    ``epsilon - alpha - delta (1, k, m, 2)`` and kappa terms ``(1, k, 1, 2)``, ``rho_hi (1,
    k, 1)``, the slanted segments and the bounding boxes."""
    seg = {key: v[None, None, :] for key, v in _segment_terms(segments).items()}
    mx, my = _point(belt.mount_xy[:, 0]), _point(belt.mount_xy[:, 1])
    rho = ia.sqrt(ia.add(ia.sqr(mx), ia.sqr(my)))  # (k, 2)
    beta = ia.atan2(my, mx)
    alpha = _point(belt.mount_angle_rad)
    gamma = belt.half_aperture_rad
    deltas = [ia.interval(-gamma, gamma)] + [_point(f * gamma) for f in offsets]
    rays = []
    for delta in deltas:
        turn = ia.add(alpha, delta)  # alpha + delta, (k, 2)
        cos_k, sin_k = ia.cos_sin(ia.sub(turn, beta))  # kappa = alpha + delta - beta
        kappa_terms = (ia.mul(rho, cos_k)[None, :, None], ia.mul(rho, sin_k)[None, :, None])
        rays.append((ia.sub(seg["eps"], turn[None, :, None]), kappa_terms))
    slanted = (segments[:, 1, 0] != segments[:, 0, 0]) & (segments[:, 1, 1] != segments[:, 0, 1])
    ends = segments
    bbox = np.stack(
        [
            ends[:, :, 0].min(axis=1),
            ends[:, :, 0].max(axis=1),
            ends[:, :, 1].min(axis=1),
            ends[:, :, 1].max(axis=1),
        ],
        axis=1,
    )  # (m, 4)
    return {
        "seg": seg,
        "rays": rays,
        "rho_hi": rho[None, :, None, 1],
        "slanted": slanted,
        "bbox": bbox,
    }


def _compiled_pieces(parts, scan, const, reject) -> None:
    """``reject (P, k)`` |= the verdicts of :func:`_k_piece_rejections` on ``parts (P, 3, 2)``,
    in blocks of pieces (the per-(piece, segment) terms are arrays)."""
    block = max(1, BLOCK_ELEMENTS // scan.segments.shape[0])
    for start in range(0, parts.shape[0], block):
        _compiled_block(parts[start : start + block], scan, const, reject[start : start + block])


def _compiled_block(parts, scan, const, reject) -> None:
    """One block of :func:`_compiled_pieces` (``reject`` is a view, updated in place)."""
    seg = const["seg"]
    g_l, we_l = pose_terms(
        parts[:, 0, None], parts[:, 1, None], {key: v[0] for key, v in seg.items()}
    )  # (P, m, 2) each
    out = np.empty(reject.shape, dtype=np.bool_)
    _k_piece_rejections(
        np.ascontiguousarray(parts),
        np.ascontiguousarray(np.stack([g_l, we_l], axis=2)),
        np.ascontiguousarray(
            np.stack([seg[key][0, 0] for key in ("ex", "ey", "L", "det_ae", "dot_ae")], axis=1)
        ),
        np.ascontiguousarray(const["bbox"]),
        np.ascontiguousarray(const["slanted"]),
        np.ascontiguousarray(np.concatenate([base for base, _ in const["rays"]], axis=0)),
        np.ascontiguousarray(
            np.stack(
                [np.stack([rc[0, :, 0], rs[0, :, 0]], axis=1) for _, (rc, rs) in const["rays"]]
            )
        ),
        np.ascontiguousarray(scan.ranges[:, 0]),
        np.ascontiguousarray(scan.ranges[:, 1]),
        np.ascontiguousarray(scan.kind),
        np.ascontiguousarray(const["rho_hi"][0, :, 0]),
        float(GUARD_M),
        out,
    )
    reject |= out


def piece_rejections(boxes, scan: SonarScan, pieces=DEFAULT_PIECES) -> np.ndarray:
    """``(N, P, k)`` bool: sensor ``i``'s reading is inconsistent with every pose of piece
    ``j`` of box ``n`` (the sub-boxes of :func:`sub_boxes`, ``P = px * py * pt``).

    ``boxes``: pose boxes ``(N, 3, 2)`` (x_m, y_m, theta_rad); ``scan``: readings, belt and map
    (:class:`intervals.sonar.scan.SonarScan`; the scan :meth:`~intervals.sonar.scan.SonarScan.restricted_to`
    the boxes gives the same soundness, faster: it keeps every segment within reach, all the hit
    test needs, and the free-space test is sound with any subset); ``pieces``: ``(px, py, pt)``.
    Sound for the cone model of :mod:`intervals.sonar.cone` at every half-aperture, tight for a
    ray (see the module doc). The kernel loops over pieces, sensors and segments, given the
    terms of about :data:`BLOCK_ELEMENTS` (piece, segment) pairs a call.
    """
    return rejections_of_pieces(boxes, scan, pieces, _compiled_pieces)


def rejections_of_pieces(boxes, scan: SonarScan, pieces, evaluate) -> np.ndarray:
    """:func:`piece_rejections` with the verdicts on the pieces from ``evaluate(parts (P, 3, 2),
    scan, constants, reject (P, k))``, which ORs them into ``reject``: the kernel's
    (:func:`_compiled_pieces`) or the numpy reference's
    (:mod:`intervals.sonar.reference.rays`), which share the checks, the empty cases and the
    cutting into pieces here."""
    boxes, pieces = _checked(boxes, scan, pieces)
    n, p, k, m = boxes.shape[0], int(np.prod(pieces)), scan.belt.count, scan.segments.shape[0]
    echo = scan.kind == ECHO
    reject = np.broadcast_to(echo & (scan.ranges[:, 0] > scan.ranges[:, 1]), (n * p, k)).copy()
    if m == 0 or n == 0:
        return (reject | echo).reshape(n, p, k)  # an echo needs a segment to come from
    parts = sub_boxes(boxes, pieces).reshape(n * p, 3, 2)
    evaluate(parts, scan, _ray_constants(scan), reject)
    return reject.reshape(n, p, k)


def ray_rejections(boxes, scan: SonarScan, pieces=DEFAULT_PIECES) -> np.ndarray:
    """``(N, k)`` bool: sensor ``i``'s reading is inconsistent with every pose of box ``n``
    (it rejects every piece; see :func:`piece_rejections`)."""
    return np.asarray(piece_rejections(boxes, scan, pieces).all(axis=1))


def joint_rejection_counts(boxes, scan: SonarScan, pieces=DEFAULT_PIECES, other=None) -> np.ndarray:
    """``(N,)`` int: over the pieces of box ``n``, the smallest number of sensors rejecting the
    piece. A box with a count above ``q`` holds no pose that leaves at most ``q`` readings
    unexplained (each pose lies in some piece). ``other``: ``(N, k)`` rejections of another
    sound test on the whole boxes (e.g. :func:`intervals.sonar.cone.sensor_verdicts`), counted in
    every piece; the count is then at least that test's own count.
    """
    rejected = piece_rejections(boxes, scan, pieces)
    if other is not None:
        rejected = rejected | np.asarray(other, dtype=bool)[:, None, :]
    return np.count_nonzero(rejected, axis=2).min(axis=1, initial=rejected.shape[2])


def joint_rejections(
    boxes,
    scan: SonarScan,
    q: int = 0,
    pieces=DEFAULT_PIECES,
    other=None,
) -> np.ndarray:
    """``(N,)`` bool: :func:`joint_rejection_counts` above ``q`` (no pose of the box leaves at
    most ``q`` readings unexplained). Stronger than counting :func:`ray_rejections`: one
    sensor may reject some pieces and another sensor the others."""
    return joint_rejection_counts(boxes, scan, pieces, other) > q
