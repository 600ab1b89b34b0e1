"""The numpy reference of the ray test (:mod:`intervals.sonar.rays`): tests and benchmarks only.

The enclosures of the module doc of :mod:`intervals.sonar.rays` (names as used there:
:func:`sine_terms`, :func:`affine_range`, :func:`ray_meeting`) evaluated on arrays of (piece,
sensor, segment) triples, without the kernel's early exits; the kernel performs the same
operations in the same order, so both give the same verdicts (tested). The checks, the
cutting into pieces and the box-independent constants are the production module's. The
production path never imports this module.
"""

from __future__ import annotations

import numpy as np

from intervals import interval as ia
from intervals.sonar.geometry import GUARD_M, down, up
from intervals.sonar.rays import (
    BLOCK_ELEMENTS,
    DEFAULT_PIECES,
    MAX_B_WIDTH_RAD,
    TRIG_TOL,
    pose_terms,
    rejections_of_pieces,
)
from intervals.sonar.scan import ECHO, FREE, SonarScan


def piece_rejections(boxes, scan: SonarScan, pieces=DEFAULT_PIECES) -> np.ndarray:
    """:func:`intervals.sonar.rays.piece_rejections` evaluated with numpy: ``(N, P, k)`` bool."""
    return rejections_of_pieces(boxes, scan, pieces, numpy_pieces)


def _mul(a_lo, a_hi, b_lo, b_hi) -> tuple[np.ndarray, np.ndarray]:
    """``[a] * [b]`` rounded outward, finite bounds (component arrays, broadcast)."""
    p = (a_lo * b_lo, a_lo * b_hi, a_hi * b_lo, a_hi * b_hi)
    return (
        down(np.minimum(np.minimum(p[0], p[1]), np.minimum(p[2], p[3]))),
        up(np.maximum(np.maximum(p[0], p[1]), np.maximum(p[2], p[3]))),
    )


def _add(a_lo, a_hi, b_lo, b_hi) -> tuple[np.ndarray, np.ndarray]:
    """``[a] + [b]`` rounded outward."""
    return down(a_lo + b_lo), up(a_hi + b_hi)


def _sub(a_lo, a_hi, b_lo, b_hi) -> tuple[np.ndarray, np.ndarray]:
    """``[a] - [b]`` rounded outward."""
    return down(a_lo - b_hi), up(a_hi - b_lo)


def _positive_quotient_bounds(c_lo, c_hi, s_lo, s_hi) -> tuple[np.ndarray, np.ndarray]:
    """``(lower, upper)`` of ``[c] / [s]`` for ``0 < s_lo <= s_hi`` (rounded outward)."""
    return (
        down(c_lo / np.where(c_lo >= 0.0, s_hi, s_lo)),
        up(c_hi / np.where(c_hi >= 0.0, s_lo, s_hi)),
    )


def sine_terms(
    b_lo, b_hi
) -> tuple[
    np.ndarray,
    tuple[np.ndarray, np.ndarray],
    tuple[np.ndarray, np.ndarray],
    tuple[np.ndarray, np.ndarray],
    np.ndarray,
]:
    """Over the intervals ``[b_lo, b_hi]`` (component arrays): ``one_sign`` (``sin`` keeps a
    strict sign), the intervals ``(lo, hi)`` of ``1 / sin``, of ``cot`` and of ``sin`` (set to
    0 where not ``one_sign``), and an upper bound of ``|sin|`` (everywhere). See the module
    doc."""
    cl, sl, ch, sh = np.cos(b_lo), np.sin(b_lo), np.cos(b_hi), np.sin(b_hi)
    narrow = b_hi - b_lo < MAX_B_WIDTH_RAD
    pos = narrow & (sl > TRIG_TOL) & (sh > TRIG_TOL)
    neg = narrow & (sl < -TRIG_TOL) & (sh < -TRIG_TOL)
    one_sign = pos | neg
    sign = np.where(neg, -1.0, 1.0)  # work with |sin| = sign sin and sign cos (exact)
    al, ah, gl, gh = sign * sl, sign * sh, sign * cl, sign * ch
    monotone = ((cl > TRIG_TOL) & (ch > TRIG_TOL)) | ((cl < -TRIG_TOL) & (ch < -TRIG_TOL))
    small = np.where(one_sign, np.minimum(al, ah) - TRIG_TOL, 1.0)
    big = np.where(monotone & narrow, np.maximum(np.abs(sl), np.abs(sh)) + TRIG_TOL, 1.0)
    inv_lo, inv_hi = down(1.0 / big), up(1.0 / small)  # 1 / |sin|
    inv = (np.where(pos, inv_lo, -inv_hi), np.where(pos, inv_hi, -inv_lo))
    # cot = (sign cos) / |sin|, decreasing: [cot(b_hi), cot(b_lo)]
    at_hi = _positive_quotient_bounds(
        gh - TRIG_TOL, gh + TRIG_TOL, np.where(one_sign, ah - TRIG_TOL, 1.0), ah + TRIG_TOL
    )
    at_lo = _positive_quotient_bounds(
        gl - TRIG_TOL, gl + TRIG_TOL, np.where(one_sign, al - TRIG_TOL, 1.0), al + TRIG_TOL
    )
    zero = np.zeros_like(b_lo)
    inv = (np.where(one_sign, inv[0], 0.0), np.where(one_sign, inv[1], 0.0))
    cot = (np.where(one_sign, at_hi[0], zero), np.where(one_sign, at_lo[1], zero))
    sin = (
        np.where(pos, small, np.where(neg, -big, 0.0)),
        np.where(pos, big, np.where(neg, -small, 0.0)),
    )
    return one_sign, inv, cot, sin, big


def affine_range(c_lo, c_hi, x, y, seg):
    """``(lo, hi)`` of ``(c g - w . e) / L`` over ``c in [c_lo, c_hi]`` and the box ``x, y``:
    the hull of its exact ranges at ``c = c_lo`` and ``c = c_hi``, where it is affine in ``x``
    and ``y`` (each once): ``c det(a, e) - a . e + x (e_x - c e_y) + y (e_y + c e_x)``."""

    def at(c):
        ex, ey, det_ae, dot_ae = (seg[key] for key in ("ex", "ey", "det_ae", "dot_ae"))
        coef_x = _sub(ex[..., 0], ex[..., 1], *_mul(c, c, ey[..., 0], ey[..., 1]))
        coef_y = _add(ey[..., 0], ey[..., 1], *_mul(c, c, ex[..., 0], ex[..., 1]))
        const = _sub(*_mul(c, c, det_ae[..., 0], det_ae[..., 1]), dot_ae[..., 0], dot_ae[..., 1])
        value = _add(*const, *_mul(x[..., 0], x[..., 1], *coef_x))
        value = _add(*value, *_mul(y[..., 0], y[..., 1], *coef_y))
        return _positive_quotient_bounds(*value, seg["L"][..., 0], seg["L"][..., 1])

    low, high = at(c_lo), at(c_hi)
    return np.minimum(low[0], high[0]), np.maximum(low[1], high[1])


def ray_meeting(b, kappa_terms, pose, x, y, seg, slanted, reading=None):
    """Enclosures ``(lo, hi)`` of ``lambda`` (eq. 1) and ``t L`` (eq. 2), component arrays
    ``(P, k, m)``, ``one_sign`` (where False, both are ``[-inf, inf]``) and an upper bound of
    ``|sin B|``.

    ``b``: the ``B`` intervals ``(P, k, m, 2)``; ``kappa_terms``: ``rho cos kappa``,
    ``rho sin kappa`` intervals ``(1, k, 1, 2)``; ``pose``: :func:`~intervals.sonar.rays.pose_terms`;
    ``x, y``: the boxes' intervals ``(P, 1, 1, 2)``; ``seg``: the segment terms;
    ``slanted``: indices of the segments parallel to neither axis. ``reading``: ``(lo, hi)``
    ``(1, k, 1)``: when given, ``t L`` is only enclosed over the poses whose ``lambda`` lies in
    it (eq. 3; empty, ``lo > hi``, where there is none).
    """
    (rc, rs), (g_l, we_l) = kappa_terms, pose
    one_sign, inv, cot, sin, sin_max = sine_terms(b[..., 0], b[..., 1])
    gl = (g_l[..., 0], g_l[..., 1])
    rc, rs, we = (rc[..., 0], rc[..., 1]), (rs[..., 0], rs[..., 1]), (we_l[..., 0], we_l[..., 1])
    rs_cot, rs_inv = _mul(*rs, *cot), _mul(*rs, *inv)
    lam = _sub(*_sub(*_mul(*gl, *inv), *rc), *rs_cot)  # (eq. 1)
    t_len = _sub(*_mul(*cot, *gl), *we)  # exact if axis-parallel
    if slanted.size:
        exact = affine_range(
            cot[0][..., slanted],
            cot[1][..., slanted],
            x,
            y,
            {key: v[:, :, slanted] for key, v in seg.items()},
        )
        t_len[0][..., slanted], t_len[1][..., slanted] = exact
    t_len = _sub(*t_len, *rs_inv)  # (eq. 2)
    if reading is not None:
        with np.errstate(invalid="ignore"):  # inf * 0: a no-echo sensor's hi (unused) times
            # the placeholder 0 of sin B where it changes sign (overwritten below)
            h = _mul(*_add(*_add(reading[0], reading[1], *rc), *rs_cot), *sin)  # (eq. 3)
        h = (np.maximum(gl[0], h[0]), np.minimum(gl[1], h[1]))
        narrowed = _sub(*_sub(*_mul(*cot, *h), *we), *rs_inv)
        none = h[0] > h[1]
        t_len = (
            np.where(none, np.inf, np.maximum(t_len[0], narrowed[0])),
            np.where(none, -np.inf, np.minimum(t_len[1], narrowed[1])),
        )
    lam = (np.where(one_sign, lam[0], -np.inf), np.where(one_sign, lam[1], np.inf))
    t_len = (np.where(one_sign, t_len[0], -np.inf), np.where(one_sign, t_len[1], np.inf))
    return lam, t_len, one_sign, sin_max


def box_gap(x, y, bbox):
    """Lower bound ``(B, 1, m)`` of the distance between the position boxes ``x, y (B, 1, 1,
    2)`` and the segments' bounding boxes ``(m, 4)``: the largest gap along an axis (rounded
    down; 0 or negative where they overlap)."""
    return np.maximum(
        np.maximum(down(bbox[:, 0] - x[..., 1]), down(x[..., 0] - bbox[:, 1])),
        np.maximum(down(bbox[:, 2] - y[..., 1]), down(y[..., 0] - bbox[:, 3])),
    )


def numpy_pieces(parts, scan, const, reject) -> None:
    """``reject (P, k)`` |= the verdicts on ``parts (P, 3, 2)``, in blocks of about
    :data:`~intervals.sonar.rays.BLOCK_ELEMENTS` (piece, sensor, segment) triples."""
    block = max(1, BLOCK_ELEMENTS // (scan.belt.count * scan.segments.shape[0]))
    for start in range(0, parts.shape[0], block):
        with np.errstate(invalid="ignore"):  # unbounded boxes: inf - inf, 0 * inf give NaN
            # bounds, which fail every strict comparison below and so keep the piece
            _block(parts[start : start + block], scan, const, reject[start : start + block])


def _block(parts, scan, const, reject) -> None:
    """One block of :func:`numpy_pieces` (``reject`` is a view, updated in place)."""
    seg, rays, rho_hi = const["seg"], const["rays"], const["rho_hi"]
    slanted = np.flatnonzero(const["slanted"])
    echo, free = scan.kind == ECHO, scan.kind == FREE
    lo, hi = scan.ranges[None, :, None, 0], scan.ranges[None, :, None, 1]
    guard = GUARD_M  # metres, in favour of keeping the box
    length_lo, length_hi = seg["L"][..., 0], seg["L"][..., 1]
    part = parts[:, :, None, None]  # (B, 3, 1, 1, 2)
    x, y, theta = part[:, 0], part[:, 1], part[:, 2]  # (B, 1, 1, 2)
    pose = pose_terms(x, y, seg)
    meetings = [
        ray_meeting(
            ia.sub(base, theta),
            kappa,
            pose,
            x,
            y,
            seg,
            slanted,
            (lo - guard, hi + guard) if i == 0 else None,
        )
        for i, (base, kappa) in enumerate(rays)
    ]
    # hit test (delta over the cone): kept unless every segment misses
    (lam_lo, lam_hi), (t_lo, t_hi), _, sin_max = meetings[0]
    g_l = pose[0]  # |lambda sin B| >= |g / L| - rho: a line far off a near-parallel ray
    off_line = down(np.maximum(g_l[..., 0], -g_l[..., 1]) - rho_hi)
    misses = (
        (lam_hi < lo - guard)
        | (lam_lo > hi + guard)
        | (t_hi < -guard)
        | (t_lo > length_hi + guard)
        | (off_line > up(up(hi + guard) * sin_max))
        | (box_gap(x, y, const["bbox"]) > up(up(hi + guard) + rho_hi))
    )
    possible = ~misses.all(axis=-1)
    # free-space test (fixed offsets): the piece surely meets a segment nearer than lo
    nearer = np.zeros(possible.shape, dtype=bool)
    for (lam_lo, lam_hi), (t_lo, t_hi), one_sign, _ in meetings[1:]:
        nearer |= (
            one_sign & (lam_lo >= 0.0) & (lam_hi < lo - guard) & (t_lo >= 0.0) & (t_hi <= length_lo)
        ).any(axis=-1)
    reject |= (echo & ~possible) | ((echo | free) & nearer)
