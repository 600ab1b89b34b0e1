r"""Tightening of a final set below the paving precision (issue 13: outer sets close to the
consistent poses).

Why. SIVIA stops bisecting at ``eps``, and the consistent poses of a tracking epoch are a thin
slanted sheet in ``(x, y, theta)``: they fill about a quarter of their own bounding box, so
even boxes contracted exactly to that hull, at ``eps``, hold about four times their volume
(BENCHMARKS.md, "Tightness"). Only boxes finer than ``eps`` can follow the sheet. Below
``eps`` this does what a SIVIA at a finer precision would do to the boxes it kept, but only to
the reported set (a few to a few tens of boxes in tracking): the rest of the pipeline (global
searches, predictions, the budget's figures) stays at ``eps``.

What. :func:`tighten` takes the boxes a paving kept and, ``levels`` times in all,
``splits`` at a time, bisects every box (:func:`intervals.boxes.bisect`: the widest scaled
axis, among those not ``idle`` when given; the two halves share the cut value, so they cover
the parent), tests the children with
a sound counted test and drops those it rejects, then contracts the survivors with a sound
contractor and drops those it empties. Testing first and contracting only the survivors costs
about a third less than the other order (most children are rejected), for the same volume
(measured on ``hall`` and ``office`` tracking epochs, 9 levels).

Idle axes. Along an idle axis of a box (:mod:`intervals.sonar.idle`: no visible wall changes
along it) the consistent poses in the box form a cylinder, so a cut across it separates no
consistent pose from an inconsistent one: it doubles the pieces for no volume. The pass never
makes it (as SIVIA), and keeps as it is a box idle along every axis (no wall in reach: no cut
can split it). On ``symmetric``, whose tracking sets hold strips up to 1.5 m long along a
wall in a few epochs (75 to 87 % of the volume), that took the ratio's 90th percentile from
6.0 to 4.9 at 9 levels under the default test budget (BENCHMARKS.md, "Tightening per
piece").

Soundness. A child is dropped only when the test proves that no pose of it is in the set, or
the contractor empties it (no such pose); every other pose of a parent lies in a kept child,
and a contracted child keeps every such pose of its own. The count returned with each box is
the test's count on that box (a number of sensors each rejecting every pose of it), so a
caller's ``count <= q`` subsets (GOMNE's ``S_q``) stay sound.

Cost. At most ``2 ** splits`` children a box per test call. The test is handed the parents
with the children (child ``n`` cut from parent ``n % P``), so that it may do once per parent
what holds for all its children: the pipeline's (:func:`intervals.localize.localize`) tests
each piece only on the (segment, sensor) pairs its parent's bounds leave
(:mod:`intervals.sonar.pieces`), which took the test's share of the pass from 4.2 to 3.1 ms an
epoch on ``hall``, 6.8 to 4.6 on ``office`` and 5.6 to 3.4 on ``apartment`` (9 levels, the
same pieces kept; BENCHMARKS.md, "Tightening at default cost"); testing a piece sensor by
sensor and leaving it once ``q + 1`` sensors reject it made a piece 1.5 to 2 times cheaper
again (0.8 us on ``hall``, 1.2 on ``corridor``; BENCHMARKS.md, "The piece test sensor by
sensor"). A call's cuts and the clamp of its contracted pieces are one compiled call each
(:func:`_pieces`, :func:`_clamped`: the same pieces, bit for bit), 4 to 7 % off a piece's
cost at 12 levels (``office_floor`` 1.16 to 1.08 us; BENCHMARKS.md, "The tracking epoch at
12 levels, phase by phase").

Under the caps a call refines only the boxes for which there is room: the set after it holds at
most ``max_boxes`` boxes and the tests stay within ``max_tested``; the others are kept as they
are, and when there is room for none the pass stops (sound either way, only coarser: refining
never has to finish). The boxes refined are those whose refinement is expected to remove the
most volume: a box's volume times the share of its parent's volume that the parent's refinement
removed (its children dropped by the test or the contractor, or contracted; 1 for the boxes
handed in, so the first call ranks them by volume), not the largest boxes: a box inside the
consistent sheet, whose cut removed nothing, no longer takes the tests of one on its edge. With
the default budget (4000 pieces, 12 levels) the tests run out in the second to fourth call on
``corridor``, ``office_floor`` and ``symmetric``, which then refines a third to two fifths of
the boxes (the median; 1 % to all). The choice of the cut axis also weighs the heading more
(:data:`HEADING_CUT_WEIGHT`, applied by :mod:`intervals.localize`). Together they took the
median tightness ratio at 12 levels from 4.0 to 3.4 on ``corridor``, 3.4 to 2.9 on
``office_floor`` and 2.5 to 2.2 on ``symmetric`` for the same pieces (another sampling seed:
4.0 to 3.4, 3.2 to 2.9, 2.4 to 2.4; the ordering alone: 4.0, 3.1, 2.5; the weight alone: 3.5,
2.9, 2.3), the tracking epochs' CPU within noise but for ``office_floor``'s p95, about 0.5 ms
more (BENCHMARKS.md, "Tightening's budget spent by expected gain"). The ordering changes only
which boxes are refined, never what a refinement keeps.

A call that removed little ends the pass (``min_removed``; :mod:`intervals.localize` hands it
:data:`MIN_REMOVED_SHARE`): the boxes it refined were those expected to remove the most, so the
next call would remove less still. On ``corridor``, ``office_floor``, ``hall`` and ``symmetric``
every call removes a third to four fifths of the volume it refines (median over the tracking
epochs at 9 levels and 4000 pieces), on ``big_hall`` (sets large by nature) the first call 15 %
and the second 6 %: the rule ends its pass after the first, for the same median ratio (2.9 to 3.0)
in epochs 1 to 2 ms cheaper (7.7-8.6 to 6.2-6.9 ms CPU), and leaves the other plans' sets as they
were but a few of ``symmetric``'s epochs (BENCHMARKS.md, "The tightening's cost against the
ratio").

When ``max_boxes`` leaves no room to refine every box ``splits`` times, a call makes fewer
bisections (down to one), so that more of the boxes are refined: on ``office_floor`` (six to
ten components, the building's repeated rooms, sharing the 10,000 boxes) 9 levels then bring
the median ratio from 4.4 to 3.3, 12 levels from 2.9 to 2.5 (BENCHMARKS.md, "Tightened sets").
"""

from __future__ import annotations

from collections.abc import Callable

import numba
import numpy as np

from intervals.boxes import bisect_into, widths
from intervals.errors import IntervalError

CountedTest = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray | None]]
"""``test(boxes (N, d, 2), parents (P, d, 2)) -> (keep (N,) bool, counts (N,) int, proof)``:
``keep`` False only when no point of the box is in the set; ``counts`` per box (e.g. the
sensors rejecting it); ``proof (N, ...)``: what the test proved of each box, handed to the
contractor with the kept boxes (e.g. which sensors reject it; None: nothing). Box ``n`` is a
part of ``parents[n % P]`` (a test may use what it proves for the parent, e.g.
:mod:`intervals.sonar.pieces`)."""

Contractor = Callable[[np.ndarray, np.ndarray | None], np.ndarray]
"""``contract(boxes (N, d, 2), proof (N, ...) or None) -> (N, d, 2)``: each row inside its input
row (clipped here) holding every point of it in the set; a row with none is NaN. ``proof``:
the test's rows of these boxes (:data:`CountedTest`)."""

IdleAxes = Callable[[np.ndarray], np.ndarray]
"""``idle(boxes (N, d, 2)) -> (N, d) bool``: the axes along which cutting a box cannot separate
points of the set from points outside it (:func:`intervals.sonar.idle.idle_axes`)."""

MAX_LEVELS = 12
"""The most bisections a box may get (each of the three pose axes halved four times)."""

HEADING_CUT_WEIGHT = 1.5
"""How much more the pass's choice of the cut axis weighs a pose box's heading width than
SIVIA's ``scale`` does: :mod:`intervals.localize` hands :func:`tighten` ``scale`` times
``(1, 1, HEADING_CUT_WEIGHT)``, so a heading width of ``w`` rad counts as ``1.5 w`` m at the
default heading scale of 1 m/rad. Of 1, 1.25, 1.5, 1.75 and 2, 1.5 (with 1.75) gave the lowest
median tightness ratios at 12 levels on ``corridor``, ``office_floor`` and ``symmetric``
(BENCHMARKS.md, "Tightening's budget spent by expected gain")."""

MIN_REMOVED_SHARE = 0.2
"""The pipeline's ``min_removed`` of :func:`tighten`: the pass ends after a call that removed less
than this share of the volume of the boxes it refined. Of 0.1, 0.2 and 0.3 (9 levels, 4000
pieces; ``big_hall``, ``corridor``, ``office_floor``, ``hall``, ``symmetric``), 0.1 changed
nearly nothing, 0.2 and 0.3 the sets of ``big_hall`` and ``symmetric`` only, alike
(``big_hall``'s epoch 7.7-8.6 to 6.2-6.7 ms CPU, about 90 to 100x real time in the closed loop
on a quiet machine; BENCHMARKS.md, "The tightening's cost against the ratio")."""

SPLITS_PER_CALL = 3
"""Bisections between two test calls: one per pose axis, about, so each call sees up to 8
children per box (fewer, larger calls: measured on ``hall`` tracking epochs, 9 levels one at a
time cost about 1.8 times 3 at a time, for the same volume)."""


def tighten(
    boxes: np.ndarray,
    counts: np.ndarray,
    test: CountedTest,
    contract: Contractor | None,
    scale: np.ndarray | None,
    levels: int,
    splits: int = SPLITS_PER_CALL,
    max_boxes: int | None = None,
    max_tested: int | None = None,
    idle: IdleAxes | None = None,
    min_removed: float = 0.0,
) -> tuple[np.ndarray, np.ndarray, int]:
    """``(boxes (K, d, 2), counts (K,), tested)``: ``boxes (N, d, 2)`` (with their ``counts
    (N,)``) refined ``levels`` bisections deep (module doc); ``tested``: the boxes the test saw.

    ``scale (d,)``: per-axis scale of the widths for the choice of the bisected axis (None:
    unscaled). ``max_boxes``: the most boxes the set may hold after a call (None: no limit; a
    set already larger is returned as it is); ``max_tested``: the most boxes the test may see
    in all (None: no limit). Under these a call refines the boxes there is room for, those
    expected to remove the most volume first (module doc).
    ``idle``: the axes of a box not to cut (module doc; None: every axis may be cut).
    ``min_removed``: the pass ends after a call whose kept pieces hold more than ``1 -
    min_removed`` of the volume of the boxes it refined (module doc; 0: never).
    """
    if not (isinstance(levels, (int, np.integer)) and 0 <= levels <= MAX_LEVELS):
        raise IntervalError(
            f"tighten: levels must be an integer in [0, {MAX_LEVELS}], got {levels!r}"
        )
    if not (isinstance(splits, (int, np.integer)) and splits >= 1):
        raise IntervalError(f"tighten: splits must be an integer >= 1, got {splits!r}")
    boxes = np.asarray(boxes, dtype=np.float64)
    counts = np.asarray(counts)
    if counts.shape != boxes.shape[:1]:
        raise IntervalError(f"tighten: {boxes.shape[0]} boxes but {counts.shape} counts")
    frozen = np.zeros(boxes.shape[0], dtype=bool)  # idle along every axis: no cut splits them
    share = np.ones(boxes.shape[0])  # per box: what its parent's refinement removed (1: given)
    done, tested = 0, 0
    while done < levels and boxes.shape[0]:
        cuts = min(splits, levels - done)
        n, m = boxes.shape[0], boxes.shape[0] - np.count_nonzero(frozen)  # m: the boxes to cut
        while cuts > 1 and max_boxes is not None and (max_boxes - n) // ((1 << cuts) - 1) < m:
            cuts -= 1  # no room to refine every box: fewer cuts, for more of the boxes
        fit = m  # the boxes this call refines: all, or those the caps leave room for
        if max_boxes is not None:  # the set after the call: at most max_boxes boxes
            fit = min(fit, (max_boxes - n) // ((1 << cuts) - 1))
        if max_tested is not None:
            fit = min(fit, (max_tested - tested) >> cuts)
        if fit <= 0:
            break
        chosen: slice | np.ndarray
        if fit == n:
            chosen, rest = slice(None), np.zeros(0, dtype=np.int64)
        else:
            gain = np.prod(widths(boxes), axis=1) * share  # volume a refinement may remove
            order = np.argsort(-gain, kind="stable")
            order = np.concatenate([order[~frozen[order]], np.flatnonzero(frozen)])
            chosen, rest = order[:fit], order[fit:]
        parents, still = boxes[chosen], None
        if idle is not None:  # a parent idle along every axis is kept as it is, not cut again
            still = np.asarray(idle(parents), dtype=bool)
            stuck = np.all(still, axis=1)
            if stuck.any():  # the call is planned again without them
                boxes = np.concatenate([parents[~stuck], parents[stuck], boxes[rest]])
                counts = np.concatenate(
                    [counts[chosen][~stuck], counts[chosen][stuck], counts[rest]]
                )
                frozen = np.concatenate([stuck[~stuck], stuck[stuck], frozen[rest]])
                share = np.concatenate([share[chosen][~stuck], share[chosen][stuck], share[rest]])
                continue
        children = _pieces(parents, scale, still, cuts)
        done += cuts
        tested += children.shape[0]
        keep, child_counts, proof = test(children, parents)
        keep = np.asarray(keep, dtype=bool)
        tested_index = np.flatnonzero(keep)  # each kept child's place among those tested
        children, child_counts = children[keep], np.asarray(child_counts)[keep]
        if contract is not None and children.shape[0]:
            proof = None if proof is None else np.asarray(proof)[keep]
            c = np.ascontiguousarray(contract(children, proof), dtype=np.float64)
            children, full = _clamped(c, np.ascontiguousarray(children))
            child_counts, tested_index = child_counts[full], tested_index[full]
        boxes = np.concatenate([children, boxes[rest]])
        counts = np.concatenate([child_counts, counts[rest]])
        frozen = np.concatenate([np.zeros(children.shape[0], dtype=bool), frozen[rest]])
        shares = _removed_shares(np.ascontiguousarray(parents), children, tested_index)
        share = np.concatenate([shares, share[rest]])
        if min_removed > 0:  # a call that removed little: the next would remove less
            refined = float(np.sum(np.prod(widths(parents), axis=1)))
            left = float(np.sum(np.prod(widths(children), axis=1)))
            if refined > 0 and left > (1.0 - min_removed) * refined:
                break
    return boxes, counts, tested


def _pieces(
    parents: np.ndarray, scale: np.ndarray | None, still: np.ndarray | None, cuts: int
) -> np.ndarray:
    """``(P << cuts, d, 2)``: ``parents (P, d, 2)`` bisected ``cuts`` times
    (:func:`intervals.boxes.bisect` with ``scale (d,)``, never across the axes ``still (P, d)``
    of a piece's parent; None: unscaled, no idle axis), each cut giving ``[lower halves, upper
    halves]`` of the pieces before it, so that piece ``n`` is a part of ``parents[n % P]``.
    One compiled call (:func:`_cut_rounds`): the boxes of ``cuts`` calls of
    :func:`intervals.boxes.bisect` and their concatenations, bit for bit."""
    parents = np.ascontiguousarray(parents, dtype=np.float64)
    d = parents.shape[1]
    return _cut_rounds(
        parents,
        np.ones(d) if scale is None else np.asarray(scale, dtype=np.float64),
        scale is not None,
        np.zeros((0, d), dtype=bool) if still is None else np.ascontiguousarray(still, dtype=bool),
        still is not None,
        int(cuts),
    )


@numba.njit(cache=True)
def _cut_rounds(parents, scale, scaled, still, has_idle, cuts):
    """:func:`_pieces`: ``cuts`` rounds of :func:`intervals.boxes.bisect_into` (its
    arguments ``scale, scaled``; the idle axes of piece ``n`` those of ``still[n % P]`` when
    ``has_idle``), the lower halves of a round before its upper halves."""
    p_count, d = parents.shape[0], parents.shape[1]
    pieces = parents.copy()
    for _ in range(cuts):
        m = pieces.shape[0]
        idle = np.zeros((m if has_idle else 0, d), dtype=np.bool_)
        if has_idle:
            for n in range(m):
                for a in range(d):
                    idle[n, a] = still[n % p_count, a]
        halves = np.empty((2 * m, d, 2))
        bisect_into(pieces, scale, scaled, idle, has_idle, halves[:m], halves[m:])
        pieces = halves
    return pieces


@numba.njit(cache=True)
def _clamped(contracted, boxes):
    """``(kept (K, d, 2), full (N,) bool)``: the rows of ``contracted (N, d, 2)`` clamped into
    those of ``boxes (N, d, 2)`` (the values of ``np.maximum`` of the lower bounds and
    ``np.minimum`` of the upper, a NaN kept), ``full``: the rows then not empty on any axis (a
    NaN compares false: emptied), ``kept``: those rows in order."""
    n, d = boxes.shape[0], boxes.shape[1]
    out = np.empty_like(boxes)
    full = np.zeros(n, dtype=np.bool_)
    count = 0
    for i in range(n):
        live = True
        for a in range(d):
            lo, hi = contracted[i, a, 0], contracted[i, a, 1]
            if not (lo >= boxes[i, a, 0] or lo != lo):  # np.maximum: the first when not less
                lo = boxes[i, a, 0]
            if not (hi <= boxes[i, a, 1] or hi != hi):  # np.minimum
                hi = boxes[i, a, 1]
            out[count, a, 0], out[count, a, 1] = lo, hi
            live = live and lo <= hi
        full[i] = live
        count += live
    return out[:count].copy(), full


@numba.njit(cache=True)
def _removed_shares(parents, children, tested_index):
    """``(K,)``: for each of ``children (K, d, 2)``, the share of its parent's volume that the
    parent's refinement removed: 1 minus the volume of the parent's children over its own
    (clipped to [0, 1]; 0 for a parent of no volume or a NaN share). Child ``k`` came from
    ``parents[tested_index[k] % P]`` (``parents (P, d, 2)``), ``tested_index (K,)`` its place
    among the children tested. Compiled: 12 us a call on 400 parents, against 73 for the numpy
    expressions (mostly the overhead of small arrays)."""
    p_count, d = parents.shape[0], parents.shape[1]
    kept = np.zeros(p_count)
    for k in range(children.shape[0]):
        v = 1.0
        for a in range(d):
            v *= children[k, a, 1] - children[k, a, 0]
        kept[tested_index[k] % p_count] += v
    removed = np.zeros(p_count)
    for p in range(p_count):
        v = 1.0
        for a in range(d):
            v *= parents[p, a, 1] - parents[p, a, 0]
        if v > 0:
            r = 1.0 - kept[p] / v
            removed[p] = 0.0 if not r > 0 else min(r, 1.0)
    shares = np.empty(children.shape[0])
    for k in range(children.shape[0]):
        shares[k] = removed[tested_index[k] % p_count]
    return shares
