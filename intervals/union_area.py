"""Area of a union of axis-aligned rectangles (Klee's measure problem in 2-D).

A sweep line moves over x through the rectangles' left and right edges; a segment tree over
the sorted distinct y edges keeps, for the rectangles the line crosses, how long a stretch of
y they cover together. Between two consecutive x events that covered length is constant, so
the union's area is ``sum_k (x_{k+1} - x_k) * L_k`` (Bentley's sweep; de Berg et al.,
*Computational Geometry*, 3rd ed., ch. 10, for the segment tree). Time ``O(N log N)``,
memory ``O(N)`` for ``N`` rectangles.

Summation order: a node's covered length is the sum of its two children's (its whole length
when some rectangle covers it all), so ``L_k`` sums the covered elementary y gaps
``y_{j+1} - y_j`` pairwise in the tree's order; the slab terms ``dx_k * L_k`` are added from
left to right with Neumaier's compensated summation. The result can differ from another
order of the same terms (a raster's cell by cell sum) in the last bits.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True)
def _covered_length(node, count, covered, whole, leaves):
    """Covered y length of ``node`` from its own cover count and its children's lengths."""
    if count[node] > 0:
        covered[node] = whole[node]
    elif node >= leaves:
        covered[node] = 0.0
    else:
        covered[node] = covered[2 * node] + covered[2 * node + 1]


@numba.njit(cache=True)
def _add_cover(lo, hi, delta, count, covered, whole, leaves):
    """Add ``delta`` (+1 or -1) to the cover count of the elementary gaps ``lo .. hi - 1``.

    Bottom-up segment tree (root 1, children ``2n`` and ``2n + 1``, gap ``j`` at leaf
    ``leaves + j``): the canonical nodes of ``[lo, hi)`` get the count, then the lengths of
    their ancestors, which all lie on the paths from leaves ``lo`` and ``hi - 1`` to the root,
    are recomputed bottom-up.
    """
    left, right = lo + leaves, hi + leaves
    first, last = left, right - 1
    while left < right:
        if left & 1:
            count[left] += delta
            _covered_length(left, count, covered, whole, leaves)
            left += 1
        if right & 1:
            right -= 1
            count[right] += delta
            _covered_length(right, count, covered, whole, leaves)
        left >>= 1
        right >>= 1
    first >>= 1
    while first >= 1:
        _covered_length(first, count, covered, whole, leaves)
        first >>= 1
    last >>= 1
    while last >= 1:
        _covered_length(last, count, covered, whole, leaves)
        last >>= 1


@numba.njit(cache=True)
def union_area(x_lo, x_hi, y_lo, y_hi):
    """Area of the union of the closed rectangles ``[x_lo, x_hi] x [y_lo, y_hi]`` (arrays
    ``(N,)`` of float64, units: those of x times those of y).

    Rectangles with ``x_lo >= x_hi`` or ``y_lo >= y_hi`` (flat or empty) add nothing; ``N = 0``
    gives 0. The bounds must be free of NaN (as :func:`intervals.boxes.as_boxes` checks): a
    rectangle with a NaN bound fails the test above and is skipped as though empty. Infinite
    bounds give an infinite or NaN area.
    """
    n = x_lo.shape[0]
    keep = np.empty(n, dtype=np.bool_)
    for i in range(n):
        keep[i] = x_lo[i] < x_hi[i] and y_lo[i] < y_hi[i]
    index = np.flatnonzero(keep)
    m = index.shape[0]
    if m == 0:
        return 0.0
    ys = np.unique(np.concatenate((y_lo[index], y_hi[index])))
    gap_lo = np.searchsorted(ys, y_lo[index])
    gap_hi = np.searchsorted(ys, y_hi[index])
    gaps = ys.shape[0] - 1
    leaves = 1
    while leaves < gaps:
        leaves *= 2
    whole = np.zeros(2 * leaves)
    whole[leaves : leaves + gaps] = ys[1:] - ys[:-1]
    for node in range(leaves - 1, 0, -1):
        whole[node] = whole[2 * node] + whole[2 * node + 1]
    count = np.zeros(2 * leaves, dtype=np.int64)
    covered = np.zeros(2 * leaves)
    # Events: rectangle k opens at x_lo (event k) and closes at x_hi (event m + k).
    event_x = np.concatenate((x_lo[index], x_hi[index]))
    order = np.argsort(event_x, kind="mergesort")
    total, compensation = 0.0, 0.0
    x_prev = event_x[order[0]]
    for e in order:
        term = (event_x[e] - x_prev) * covered[1]
        t = total + term  # Neumaier: keep the low-order bits lost by each addition
        if abs(total) >= abs(term):
            compensation += (total - t) + term
        else:
            compensation += (term - t) + total
        total = t
        x_prev = event_x[e]
        k = e if e < m else e - m
        _add_cover(gap_lo[k], gap_hi[k], 1 if e < m else -1, count, covered, whole, leaves)
    return total + compensation
