"""SIVIA's bisection rounds compiled (numba): one call per level instead of numpy passes.

:func:`split_rounds` bisects every box at the middle of its widest scaled dimension that is
not idle (as :func:`intervals.boxes.bisect` when none is: the same float operations,
``lo + (hi - lo) / 2``, the first widest axis on ties), sets aside the children no wider than
``eps`` along their axes not idle (scaled, as :func:`intervals.boxes.max_width` when none is;
:func:`intervals.sivia.cut_width`) and bisects the others again, ``times`` rounds in all. A
child inherits the idle axes of its box (:func:`intervals.sivia.sivia`'s ``idle``). The
children come out in the order of the numpy rounds it replaces (each round: every left child,
then every right child; the narrow ones of round 1, of round 2, ..., then those still wide),
so SIVIA stores and tests the same boxes in the same order. A tracking epoch spends a
millisecond or so in those numpy rounds (a dozen small array passes per level); this is one
loop over the boxes.
"""

from __future__ import annotations

import numba
import numpy as np

from intervals.boxes import copy_box


@numba.njit(cache=True)
def _widest(boxes, i, scale, idle, owner):
    """The first axis of largest scaled width of row ``i`` of ``boxes (N, d, 2)`` among those
    not idle in row ``owner`` of ``idle (M, d)`` (0 if every axis is idle)."""
    axis, best = 0, -1.0
    for a in range(boxes.shape[1]):
        w = (boxes[i, a, 1] - boxes[i, a, 0]) * scale[a]
        if not idle[owner, a] and w > best:
            axis, best = a, w
    return axis


@numba.njit(cache=True)
def split_rounds(boxes, eps, scale, times, idle):
    """``(children (M, d, 2), parents (M,) int64)``: ``boxes (N, d, 2)`` (each wider than
    ``eps`` along an axis not idle) bisected ``times`` rounds (module doc), never across the
    axes ``idle (N, d) bool`` of their box; ``parents``: the row of ``boxes`` each child lies
    in. ``scale (d,)`` positive."""
    n, d = boxes.shape[0], boxes.shape[1]
    todo, owners = boxes.copy(), np.arange(n)
    out = np.empty((n << times, d, 2))
    out_owners = np.empty(n << times, dtype=np.int64)
    count = 0
    for _ in range(times):
        m = todo.shape[0]
        children = np.empty((2 * m, d, 2))
        child_owners = np.empty(2 * m, dtype=np.int64)
        wide = 0
        for side in range(2):  # the left children, then the right ones
            for i in range(m):
                owner = owners[i]
                axis = _widest(todo, i, scale, idle, owner)
                lo, hi = todo[i, axis, 0], todo[i, axis, 1]
                cut = lo + (hi - lo) / 2.0
                narrow = True  # the child written at out[count], kept there if narrow
                for a in range(d):
                    c_lo, c_hi = todo[i, a, 0], todo[i, a, 1]
                    if a == axis:
                        if side == 0:
                            c_hi = cut
                        else:
                            c_lo = cut
                    if not idle[owner, a] and (c_hi - c_lo) * scale[a] > eps:
                        narrow = False
                    out[count, a, 0], out[count, a, 1] = c_lo, c_hi
                if narrow:
                    out_owners[count] = owner
                    count += 1
                else:
                    copy_box(out, count, children, wide)
                    child_owners[wide] = owner
                    wide += 1
        todo, owners = children[:wide], child_owners[:wide]
    for i in range(todo.shape[0]):
        copy_box(todo, i, out, count)
        out_owners[count] = owners[i]
        count += 1
    return out[:count], out_owners[:count]
