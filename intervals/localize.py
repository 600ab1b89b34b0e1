r"""Localisation from a sonar scan: paving by SIVIA, q-relaxation and GOMNE (paper 002 s. 3).

The box tests (:mod:`intervals.sonar.cone`, :mod:`intervals.sonar.room`,
:mod:`intervals.sonar.rays`) give, per box, which sensors' readings no pose of the box can
explain. Here they are combined:

* **q-relaxation**: a box is OUTSIDE when the in-room test rejects it or more than ``q`` sensors
  reject it; INSIDE (if inner tests are on) when it is inside the room and at most ``q``
  sensors are not certainly satisfied; else UNDECIDED (:func:`box_test`).
* :func:`localize` paves ``{p in initial : at most q sensors inconsistent}`` with SIVIA;
  :func:`gomne` raises ``q`` from 0 to the smallest value leaving a non-empty set.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from intervals.boxes import (
    DEFAULT_HEADING_SCALE_M_PER_RAD,
    Subpaving,
    as_boxes,
    clip_to_boxes,
    meets_any_box,
    pose_scale,
)
from intervals.errors import IntervalError
from intervals.imagesp import coarsen
from intervals.sivia import DEFAULT_MAX_BOXES, INSIDE, OUTSIDE, UNDECIDED, cut_width, sivia
from intervals.sonar import contractor, idle
from intervals.sonar.cone import sensor_verdicts
from intervals.sonar.pieces import piece_rejections
from intervals.sonar.room import room_verdicts
from intervals.sonar.scan import SonarBelt, SonarScan
from intervals.tighten import HEADING_CUT_WEIGHT, MAX_LEVELS, MIN_REMOVED_SHARE, tighten

MIN_LEVEL_BOXES = 128
"""SIVIA levels of fewer boxes are bisected more (see :func:`intervals.sivia.sivia`)."""

TESTS_PER_BOX = 20
"""With a budget of ``max_boxes``, SIVIA may test at most this many times ``max_boxes`` boxes in
one pass (:func:`localize`): about 1.5 s of the compiled test at 8 us a box for the tracker's
default 10 000, above the 190 000 boxes a global search of a 30 x 30 m, 184-segment map
tests."""

GLOBAL_SPLITS_PER_LEVEL = 2
"""Bisections per SIVIA level in the tracker's global searches (3 elsewhere, :func:`localize`).
The big levels of a global search are mostly rejected one bisection below the level where
they are undecided, so cutting twice a level instead of three times tests fewer boxes
(office_floor's global search: 2.1 s instead of 3.7 s on an idle machine, the same set; small
tracking sets are faster at 3, with fewer test calls)."""

SIVIA_TEST_PIECES = 1
"""With ``tighten_max_tested``, the pieces of the tightening one SIVIA box test stands for: the
pass tests at most ``tighten_max_tested`` minus this many times SIVIA's box tests of the same
call, floored at 0 (:func:`_pave`), so the call's box tests, SIVIA's and the pass's, stay
within ``tighten_max_tested``. By cost a SIVIA box test is about 8 pieces (BENCHMARKS.md, "The
tracking epoch at 12 levels, phase by phase", ``office_floor``: the multi-room epochs test 440
to 850 boxes for 4.2 to 6.8 ms of box test, contractor and loop, 7.9 to 9.5 us a tested box;
4000 pieces cost 4.45 ms, 1.1 us a piece), but 8 left the pass no pieces in those epochs and
few in the others: at 12 levels the median tightness ratio went from 2.9 to 3.4 on
``office_floor``, 3.4 to 5.3 on ``corridor``, 2.2 to 3.3 on ``symmetric`` (2: 3.2, 3.5, 2.3).
1 keeps them (3.0, 3.3, 2.3) and takes ``office_floor``'s tracking CPU p95 from about 10.8 to
9.6 ms (BENCHMARKS.md, "One epoch budget for SIVIA and the pass")."""

RAY_TEST_AUTO_MAX_HALF_APERTURE_RAD = 0.1
"""With ``ray_test=None`` (auto), :mod:`intervals.sonar.rays` joins the box test when the belt's
half-aperture is at most this. Measured (``benchmarks/intervals_vs_codac.py``, tracking epochs
in ``hall``): the outer volume with the ray test over the volume without is 0.37-0.74 for
half-apertures of 0.003-0.1 rad but 0.90 for the default belt's 12.5 deg (0.22 rad), where it
costs about 5 ms an epoch (more than the rest of the epoch): worth it on thin cones, a choice
(``ray_test=True``) on wide ones."""


@numba.njit(cache=True)
def _sensor_counts(reject, certain, q, inner):
    """``(rejects (N,) int64, out (N,) bool, inside (N,) bool)`` from the sensor verdicts
    ``reject, certain (N, k)``: the number of sensors rejecting each box, more than ``q`` of
    them, and (with ``inner``, else False) at most ``q`` sensors not certainly satisfied."""
    n, k = reject.shape
    rejects = np.zeros(n, dtype=np.int64)
    out, inside = np.empty(n, dtype=np.bool_), np.zeros(n, dtype=np.bool_)
    for i in range(n):
        unsure = 0
        for j in range(k):
            rejects[i] += reject[i, j]
            unsure += not certain[i, j]
        out[i] = rejects[i] > q
        inside[i] = inner and unsure <= q
    return rejects, out, inside


@numba.njit(cache=True)
def _verdict_codes(out, inside):
    """``(N,) int8``: OUTSIDE where ``out``, else INSIDE where ``inside``, else UNDECIDED."""
    verdicts = np.empty(out.size, dtype=np.int8)
    for i in range(out.size):
        verdicts[i] = OUTSIDE if out[i] else (INSIDE if inside[i] else UNDECIDED)
    return verdicts


def _test_and_counts(boxes, scan: SonarScan, q: int, inner: bool, probe=None, parents=None):
    """``(verdicts (N,) int8, rejects (N,), reject (N, k) bool)``: :func:`box_test`, the number
    of sensors rejecting each box, and which. ``probe (N, 3, 2)``: boxes within ``boxes`` whose
    sensor verdicts hold for them (:func:`intervals.sonar.idle.probes`; None: ``boxes``); the
    in-room test always sees ``boxes``. ``parents (P, 3, 2)`` (without ``inner`` or ``probe``):
    box ``n`` is a part of ``parents[n % P]``, and the sensors' test is
    :func:`intervals.sonar.pieces.piece_rejections` (sound, on the pairs the parent leaves; a
    box's row is left once ``q + 1`` sensors reject it, so the count of a rejected box may be
    below the full count, its verdict the same; the in-room test skips the boxes of parents
    wholly inside the room, with the same verdicts). ``boxes`` are checked pose boxes
    (:func:`_pose_boxes`, or SIVIA's boxes), not checked again."""
    if parents is not None:
        reject = piece_rejections(boxes, parents, scan, int(q) + 1)
        certain = np.zeros_like(reject)
    else:
        reject, certain = sensor_verdicts(boxes if probe is None else probe, scan, inner, True)
    rejects, out, inside = _sensor_counts(reject, certain, int(q), bool(inner))
    if scan.boundary is not None:
        # the in-room test only matters for the boxes the sensors do not reject
        live = np.flatnonzero(~out)
        if parents is not None and live.size:
            # a piece of a parent wholly inside the room is wholly inside it (no edge within
            # GUARD_M of its rectangle, a part of the parent's; the segment between the two
            # centres crosses no edge, so the ray casts from them, both more than GUARD_M from
            # every edge, agree): its verdict is the one room_verdicts would give, so only the
            # pieces of the other parents are tested (corridor, 12 levels: 0.16 to 0.04 us a
            # piece; BENCHMARKS.md, "The tightening pass per piece")
            parent_in = room_verdicts(parents, scan.boundary)[1]
            live = live[~parent_in[live % parents.shape[0]]]
        room_out, room_in = room_verdicts(boxes[live], scan.boundary)
        out[live] |= room_out
        inside[live] &= room_in
    return _verdict_codes(out, inside), rejects, reject


MAX_WITHIN_REGIONS = 256
"""The most regions ``within`` may hold (:func:`localize`): each test call compares its
boxes with every region."""


def box_test(boxes, scan: SonarScan, q: int = 0, inner: bool = True) -> np.ndarray:
    """SIVIA test ``(N,) int8``: OUTSIDE when the in-room test or more than ``q`` sensors reject
    the box, INSIDE when (``inner``) it is inside the room and at most ``q`` sensors are not
    certainly satisfied, else UNDECIDED."""
    return _test_and_counts(_pose_boxes(boxes, "box test boxes"), scan, q, inner)[0]


def _checked_q(q) -> None:
    if not (isinstance(q, (int, np.integer)) and q >= 0):
        raise IntervalError(f"q must be a non-negative integer, got {q!r}")


def _checked_budget(max_boxes) -> None:
    if max_boxes is not None and not (isinstance(max_boxes, (int, np.integer)) and max_boxes >= 8):
        raise IntervalError(f"max_boxes must be None or an integer >= 8, got {max_boxes!r}")


def _checked_contract(contract) -> bool:
    if not isinstance(contract, bool):
        raise IntervalError(f"contract must be True or False, got {contract!r}")
    return contract


def _checked_rounds(rounds) -> int:
    if not (isinstance(rounds, (int, np.integer)) and not isinstance(rounds, bool) and rounds >= 0):
        raise IntervalError(f"shave_rounds must be an integer >= 0, got {rounds!r}")
    return int(rounds)


def _checked_levels(levels) -> int:
    if not (
        isinstance(levels, (int, np.integer))
        and not isinstance(levels, bool)
        and 0 <= levels <= MAX_LEVELS
    ):
        raise IntervalError(
            f"tighten_levels must be an integer in [0, {MAX_LEVELS}], got {levels!r}"
        )
    return int(levels)


def _checked_tighten_tests(tests) -> int | None:
    if tests is not None and not (
        isinstance(tests, (int, np.integer)) and not isinstance(tests, bool) and tests >= 0
    ):
        raise IntervalError(f"tighten_max_tested must be None or an integer >= 0, got {tests!r}")
    return None if tests is None else int(tests)


def _checked_whole_boxes(whole_boxes) -> bool:
    if not isinstance(whole_boxes, bool):
        raise IntervalError(f"whole_boxes must be True or False, got {whole_boxes!r}")
    return whole_boxes


def _pose_boxes(boxes, name: str) -> np.ndarray:
    """Checked pose boxes ``(N, 3, 2)`` (:func:`intervals.boxes.as_boxes`, ``name`` in the
    errors)."""
    boxes = as_boxes(boxes, name)
    if boxes.shape[1] != 3:
        raise IntervalError(f"{name} must be (N, 3, 2), got {boxes.shape}")
    return boxes


def uses_ray_test(ray_test: bool | None, belt: SonarBelt) -> bool:
    """Whether the ray test joins the box test (``None``: by the belt's aperture, see
    :data:`RAY_TEST_AUTO_MAX_HALF_APERTURE_RAD`)."""
    if ray_test is None:
        return belt.half_aperture_rad <= RAY_TEST_AUTO_MAX_HALF_APERTURE_RAD
    if not isinstance(ray_test, bool):
        raise IntervalError(f"ray_test must be True, False or None (auto), got {ray_test!r}")
    return ray_test


def _pave(
    local: SonarScan,
    boxes,
    eps,
    q,
    scale,
    inner,
    splits_per_level,
    ray_test,
    max_boxes,
    max_kept=None,
    within=None,
    contract=True,
    shave_rounds=0,
    tighten_levels=0,
    whole=False,
    tests_per_box=TESTS_PER_BOX,
    tighten_max_tested=None,
):
    """SIVIA on ``boxes`` at relaxation ``q``: ``(paving, rejects (Nb,), merged, held (Ni,))``
    with the number of sensors rejecting each boundary box (``merged``: see below), kept from
    the SIVIA level that stored the box (the boundary boxes are the undecided boxes no wider
    than ``eps``, in the order SIVIA met them; checked, and recomputed if SIVIA ever stored
    them otherwise), and likewise the number rejecting each inner box (``held``; with
    ``inner`` only, else empty).

    ``max_boxes`` (None: no budget): the budget of :func:`localize`. SIVIA may then test at
    most ``tests_per_box`` (default :data:`TESTS_PER_BOX`) ``* max_boxes`` boxes, best first
    (the boxes fewest sensors reject first, see :func:`intervals.sivia.sivia`), and hand at most ``max_boxes`` to one
    test call. When it is cut short the boxes it left untested (children of undecided boxes)
    are tested once, in chunks, and those the test rejects are dropped (each rejection is
    sound for every pose of the box); only then, if the set still holds more than
    ``max_kept`` boxes (default ``max_boxes``), is it merged into at most that many
    (:func:`intervals.imagesp.coarsen`) and retested (``merged`` true). A set cut short or
    merged is ``coarse``.

    With ``ray_test`` the boxes SIVIA would store are also tested by
    :func:`intervals.sonar.rays.joint_rejection_counts` (pieces of the box, each rejected by the
    ray test or the cone test of its sensors): a box whose every piece is rejected by more
    than ``q`` sensors holds no pose with at most ``q`` bad readings, so it is OUTSIDE. Its
    count is never below the cone test's, so GOMNE's ``count <= q`` sets stay sound. Only the
    stored boxes are tested: rejecting those is all that changes the outer set (testing every
    level gave the same volumes at twice the time).

    With ``contract`` every SIVIA frontier is first contracted by
    :func:`intervals.sonar.contractor.contract` at the same ``q`` (it keeps every pose with at
    most ``q`` wrong readings, so the set and the counts stay sound), and the boundary boxes of
    a paving not cut short are shaved (:func:`_shaved`, ``shave_rounds`` rounds), within the
    budget's tests when there is one (fewer rounds, or none, when the tests left do not allow
    them).

    With ``tighten_levels`` the boundary boxes of a paving not cut short are first refined
    below ``eps`` (:func:`intervals.tighten.tighten`: that many bisections, each child tested
    as SIVIA's stored boxes are, at ``q``, and contracted when ``contract``), each keeping the
    count of its own test; with a budget, within ``max_boxes`` boxes and the tests left (the
    boxes expected to remove the most volume refined first, the rest kept as they are; the cut
    axis chosen with the heading weighed :data:`intervals.tighten.HEADING_CUT_WEIGHT` times
    more than in SIVIA), and within ``tighten_max_tested`` minus
    :data:`SIVIA_TEST_PIECES` times SIVIA's box tests of this call, floored at 0 (None: no
    limit of its own; a SIVIA that tested many boxes leaves a coarser, still sound,
    tightening), ending after a call that removed less than
    :data:`intervals.tighten.MIN_REMOVED_SHARE` of the volume it refined, before any shaving.
    """
    stored, counts, tested = [], [], [0]
    walls = idle.scan_walls(local) if whole else None
    still = (lambda b: idle.idle_axes(b, local, walls)) if whole else None
    held, held_counts = [], []  # the INSIDE boxes (with ``inner``) and their counts, in order
    if within is not None:  # a box meeting none of these holds no pose of the set: OUTSIDE
        within = as_boxes(within, "within")

    def recount(b, reject):
        from intervals.sonar import rays  # its kernels compile only for runs with the ray test

        return rays.joint_rejection_counts(b, local, rays.DEFAULT_PIECES, other=reject)

    def sonar_test(b):
        tested[0] += b.shape[0]
        axes = None if still is None else still(b)
        probe = None if axes is None else idle.probes(b, axes)
        verdicts, rejects, reject = _test_and_counts(b, local, q, inner, probe)
        # an INSIDE box in no single region may hold poses outside them
        if inner and within is not None and (ins := np.flatnonzero(verdicts == INSIDE)).size:
            verdicts[ins[~clip_to_boxes(b[ins], within)[1]]] = UNDECIDED
        keep = (verdicts == UNDECIDED) & (cut_width(b, scale, axes) <= eps)
        if ray_test and (idx := np.flatnonzero(keep)).size:
            rejects[idx] = recount(b[idx], reject[idx])
            out = idx[rejects[idx] > q]
            verdicts[out] = OUTSIDE
            keep[out] = False
        stored.append(b[keep])
        counts.append(rejects[keep])
        if inner:
            held.append(b[verdicts == INSIDE])
            held_counts.append(rejects[verdicts == INSIDE])
        # under a budget, the boxes fewest sensors reject go first; SIVIA never cuts a box
        # across its idle axes (found once a box, here)
        return verdicts, rejects, axes

    def inner_counts(boxes):  # the count of each INSIDE box (recomputed if not as recorded)
        done = np.concatenate([*held, boxes[:0]])
        if np.array_equal(done, boxes):
            return np.concatenate([*held_counts, np.zeros(0, dtype=np.int64)])
        return np.count_nonzero(sensor_verdicts(boxes, local, False, True)[0], axis=1)

    def test(b):
        if within is None:
            return sonar_test(b)
        meets = meets_any_box(b, within)
        verdicts = np.full(b.shape[0], OUTSIDE, dtype=np.int8)
        rejects = np.full(b.shape[0], local.belt.count + 1, dtype=np.int64)
        axes = None if still is None else np.zeros(b.shape[:2], dtype=bool)
        if meets.any():
            verdicts[meets], rejects[meets], met_axes = sonar_test(b[meets])
            if axes is not None:
                axes[meets] = met_axes
        return verdicts, rejects, axes

    def counted(b, parents):  # the test of the tightening: (kept, counts) as SIVIA's stored
        # boxes, each piece on the (segment, sensor) pairs its parent leaves
        verdicts, rejects, reject = _test_and_counts(b, local, q, False, parents=parents)
        keep = verdicts != OUTSIDE
        if ray_test and (idx := np.flatnonzero(keep)).size:
            rejects[idx] = recount(b[idx], reject[idx])
            keep[idx] = rejects[idx] <= q
        # the sensors rejecting every pose of a piece: its contractor takes them as wrong
        return keep, rejects, reject

    def contracted(b):  # the boxes clipped to the regions of ``within``, then by the echoes
        if within is None:
            return contractor.contract(b, local, q, validated=True)
        # clipped: the boxes meeting no region (emptied) and those with an idle axis (kept
        # whole along it, they may reach far out of the regions: big_hall's mean set 3.3 m²
        # against 15 unclipped); any other clipped box leaves SIVIA's grid and the next
        # epochs' sets grew (corridor's mean 0.072 to 0.104 m², tracking_epochs.py)
        clipped, held = clip_to_boxes(b, within)
        live = np.all(clipped[..., 0] <= clipped[..., 1], axis=1)
        clip = ~live
        if still is not None and (cut := live & ~held).any():  # a box in one region: as is
            clip[cut] = still(b[cut]).any(axis=1)
        b = np.where(clip[:, None, None], clipped, b)
        if contract and live.any():
            b[live] = contractor.contract(b[live], local, q, validated=True)
        return b

    paving = sivia(
        test,
        boxes,
        eps,
        scale,
        max_boxes=DEFAULT_MAX_BOXES if max_boxes is None else min(max_boxes, DEFAULT_MAX_BOXES),
        splits_per_level=splits_per_level,
        min_level_boxes=MIN_LEVEL_BOXES,
        max_tested=None if max_boxes is None else int(tests_per_box * max_boxes),
        contract=contracted if contract or within is not None else None,
    )
    kept_cap = max_boxes if max_kept is None else max_kept
    over = max_boxes is not None and paving.outer.shape[0] > kept_cap
    if not (paving.coarse or over):
        rejects = np.concatenate(counts) if counts else np.zeros(0, dtype=np.int64)
        if counts and not np.array_equal(np.concatenate(stored), paving.boundary):
            reject = sensor_verdicts(paving.boundary, local, False, True)[0]
            rejects = (
                recount(paving.boundary, reject) if ray_test else np.count_nonzero(reject, axis=1)
            )
        if tighten_levels and paving.boundary.shape[0]:  # within the budget's tests left
            left = None if max_boxes is None else max(int(tests_per_box * max_boxes) - tested[0], 0)
            if tighten_max_tested is not None:  # the call's budget, SIVIA's tests taken off
                share = max(tighten_max_tested - SIVIA_TEST_PIECES * tested[0], 0)
                left = share if left is None else min(left, share)
            boundary, rejects, seen = tighten(
                paving.boundary,
                rejects,
                counted,
                (
                    (lambda b, wrong: contractor.contract(b, local, q, validated=True, wrong=wrong))
                    if contract
                    else None
                ),
                scale * pose_scale(HEADING_CUT_WEIGHT),
                tighten_levels,
                max_boxes=max_boxes,
                max_tested=left,
                idle=still,
                min_removed=MIN_REMOVED_SHARE,
            )
            tested[0] += seen
            paving = Subpaving(paving.inner, boundary, coarse=paving.coarse)
        n = paving.boundary.shape[0]
        rounds = shave_rounds
        if max_boxes is not None and n:  # within the budget of tests (6 n slices a round)
            rounds = min(rounds, max(int(tests_per_box * max_boxes) - tested[0], 0) // (6 * n))
        if contract and n and rounds:
            paving, rejects = _shaved(paving, rejects, local, q, rounds, max_boxes)
        return paving, rejects, False, inner_counts(paving.inner)

    def retest(b):  # (kept boxes, their counts): the boxes the test does not reject
        kept, kept_counts = [b[:0]], [np.zeros(0, dtype=np.int64)]
        for chunk in np.array_split(b, max(1, -(-b.shape[0] // (max_boxes or DEFAULT_MAX_BOXES)))):
            verdicts, rejects, reject = _test_and_counts(chunk, local, q, False)
            if ray_test:
                rejects = recount(chunk, reject)
            keep = (verdicts != OUTSIDE) & (rejects <= q)
            kept.append(chunk[keep])
            kept_counts.append(rejects[keep])
        return np.concatenate(kept), np.concatenate(kept_counts)

    # Cut short: the boundary holds the boxes SIVIA stored (tested, each with its count) and
    # then the boxes it left untested (children of undecided boxes); those are tested now,
    # once (most of a frontier's boxes are rejected at the next level), before any merge.
    done = np.concatenate([*stored, paving.boundary[:0]])
    rejects_done = np.concatenate([*counts, np.zeros(0, dtype=np.int64)])
    if not np.array_equal(done, paving.boundary[: done.shape[0]]):
        done, rejects_done = done[:0], rejects_done[:0]  # not in SIVIA's order: all retested
    # at most as many retests as the budget's tests; boxes beyond are kept whole, untested
    cap = int(tests_per_box * max_boxes) if max_boxes is not None else paving.boundary.shape[0]
    rest = paving.boundary[done.shape[0] :]
    tested, tested_counts = retest(rest[:cap])
    untested = rest[cap:]
    boundary = np.concatenate([done, tested, untested])
    # an untested box counts no rejecting sensor: kept in every S_q (sound, coarser)
    rejects = np.concatenate([rejects_done, tested_counts, np.zeros(untested.shape[0], np.int64)])
    inner_boxes, merged = paving.inner, False
    if max_boxes is not None and inner_boxes.shape[0] + boundary.shape[0] > kept_cap:
        # still too many: merged into at most kept_cap boxes (a coarser cover), retested
        cells = coarsen(np.concatenate([inner_boxes, boundary]), kept_cap, scale)
        boundary, rejects = retest(cells)
        inner_boxes, merged = inner_boxes[:0], True
    return Subpaving(inner_boxes, boundary, coarse=True), rejects, merged, inner_counts(inner_boxes)


def _shaved(paving: Subpaving, rejects, local: SonarScan, q: int, rounds, max_boxes):
    """The boundary boxes narrowed by :func:`intervals.sonar.contractor.shave` (cone and room
    tests at ``q``, ``rounds`` rounds, at most ``max_boxes`` slices a call), with their counts: a
    box's count, the sensors rejecting it, holds for its parts (each rejects every pose of the
    box), so GOMNE's ``count <= q`` sets stay sound."""
    boxes = paving.boundary

    def rejected(slices):
        return _test_and_counts(slices, local, q, False)[0] == OUTSIDE

    shaved, rows = contractor.shave(boxes, rejected, local, q, rounds, max_per_call=max_boxes)
    return Subpaving(paving.inner, shaved, coarse=paving.coarse), rejects[rows]


def localize(
    scan: SonarScan,
    initial,
    eps: float,
    q: int = 0,
    heading_scale_m_per_rad: float = DEFAULT_HEADING_SCALE_M_PER_RAD,
    inner: bool = False,
    splits_per_level: int = 3,
    ray_test: bool | None = None,
    max_boxes: int | None = None,
    max_kept: int | None = None,
    contract: bool = True,
    shave_rounds: int = 0,
    tighten_levels: int = 0,
    tighten_max_tested: int | None = None,
) -> Subpaving:
    """Pose set ``{p in initial : at most q sensors inconsistent}`` paved by SIVIA.

    ``initial``: a pose box ``(3, 2)`` or a subpaving ``(N, 3, 2)``. Only the segments within
    reach of the initial boxes take part. Levels of fewer than :data:`MIN_LEVEL_BOXES` boxes
    are bisected further before the test (see :func:`intervals.sivia.sivia`).
    ``inner=False`` (default) skips the inner acceptance
    test: the outer approximation is what the fusion uses, and it is cheaper.
    ``ray_test``: add :mod:`intervals.sonar.rays` to the test of the boxes kept (``None``: when the
    cones are thin, :data:`RAY_TEST_AUTO_MAX_HALF_APERTURE_RAD`).
    ``max_boxes``: a budget (None: none). The set then holds at most ``max_boxes`` boxes and
    SIVIA tests at most :data:`TESTS_PER_BOX` ``* max_boxes``, at most ``max_boxes`` per
    call, so time and memory are bounded whatever the map, the readings or ``eps``; where the
    budget cuts the paving short or merges its boxes the set is a coarser cover of the same
    poses, marked ``coarse`` (:attr:`intervals.boxes.Subpaving.coarse`). ``max_kept``: with a
    budget, the most boxes the set may hold instead (default ``max_boxes``; more keeps more of
    what the budget refined, for a caller that refines the set further, see
    :class:`intervals.tracker.Refinement`).
    ``contract``: contract every SIVIA frontier by :mod:`intervals.sonar.contractor` before
    the test (the same set or a tighter one: it only removes poses with more than ``q`` wrong
    readings). ``shave_rounds``: with ``contract``, rounds of
    :func:`intervals.sonar.contractor.shave` on the boxes kept (0: none; each round tighter and
    dearer, see :data:`intervals.sonar.contractor.SHAVE_ROUNDS`). ``tighten_levels``: bisections
    below ``eps`` of the boxes kept, each piece tested and contracted
    (:mod:`intervals.tighten`; 0: none; 9 halves each axis about three times), before shaving.
    ``tighten_max_tested``: the budget of the paving and the tightening in pieces: the
    tightening may test that many pieces minus :data:`SIVIA_TEST_PIECES` per box SIVIA tested,
    floored at 0 (None: no limit but the budget's; under it the boxes expected to remove the
    most volume are refined first, the others kept as they are).
    """
    _checked_q(q)
    _checked_budget(max_boxes)
    boxes = _pose_boxes(initial, "initial pose boxes")
    scale = pose_scale(heading_scale_m_per_rad)
    local = scan.restricted_to(boxes)
    return _pave(
        local,
        boxes,
        eps,
        q,
        scale,
        inner,
        splits_per_level,
        uses_ray_test(ray_test, scan.belt),
        max_boxes,
        max_kept,
        None,
        _checked_contract(contract),
        _checked_rounds(shave_rounds),
        _checked_levels(tighten_levels),
        tighten_max_tested=_checked_tighten_tests(tighten_max_tested),
    )[0]


@dataclass(frozen=True)
class GomneResult:
    """Outcome of :func:`gomne`.

    ``q``: GOMNE's estimate, the smallest number of outliers that leaves a non-empty set (None
    when even ``q_max`` leaves it empty: the data are inconsistent); ``q_set``: the relaxation
    of the returned ``paving`` (``q_max`` when guaranteed, else ``q``).
    """

    paving: Subpaving
    q: int | None
    q_set: int | None
    merged: bool = False
    """The budget merged the set's boxes (a set finer than ``max_kept`` boxes would hold)."""

    @property
    def consistent(self) -> bool:
        """False when no ``q <= q_max`` explains the data (never clamp to this set)."""
        return self.q is not None


def gomne(
    scan: SonarScan,
    initial,
    eps: float,
    q_max: int,
    heading_scale_m_per_rad: float = DEFAULT_HEADING_SCALE_M_PER_RAD,
    inner: bool = False,
    guaranteed: bool = True,
    ray_test: bool | None = None,
    max_boxes: int | None = None,
    max_kept: int | None = None,
    splits_per_level: int = 3,
    within=None,
    contract: bool = True,
    shave_rounds: int = 0,
    tighten_levels: int = 0,
    whole_boxes: bool = False,
    tests_per_box: float = TESTS_PER_BOX,
    tighten_max_tested: int | None = None,
) -> GomneResult:
    """GOMNE: the smallest ``q <= q_max`` whose q-relaxed set is not empty.

    The sets are nested (``S_0 ⊆ S_1 ⊆ ... ⊆ S_qmax``), so ``S_qmax`` is paved first (empty:
    inconsistent, stop); without inner boxes ``S_q`` is read off the number of sensors rejecting
    each of its boxes, recorded during that pass; with them ``q = 0, 1, ...`` are tried on its
    boxes (a SIVIA pass each).

    ``guaranteed=True`` returns ``S_qmax``: it holds the true pose whenever at most ``q_max``
    readings are outliers. GOMNE's own set ``S_q`` (``guaranteed=False``) is smaller but can
    miss the truth: outliers that happen to agree with some other pose make fewer than the
    actual number of outliers suffice, and ``S_q`` then holds only those other poses.
    ``ray_test``, ``max_boxes``, ``max_kept``, ``splits_per_level``, ``contract``,
    ``shave_rounds``, ``tighten_levels`` and ``tighten_max_tested``: as in :func:`localize`.
    ``within`` (None, or at most :data:`MAX_WITHIN_REGIONS` boxes ``(M, 3,
    2)`` known to hold every pose of the set, e.g. the tracker's prediction of each
    component): SIVIA rejects the boxes meeting none of them without testing them, so the
    set is the one paved from ``initial`` less what lies outside ``within`` (more regions:
    ignored). A coarse ``S_qmax`` gives a coarse ``S_q``; the tracker's global searches use
    :data:`GLOBAL_SPLITS_PER_LEVEL`.
    ``whole_boxes``: keep whole the boxes the scan cannot split. The inner acceptance runs in
    the ``q_max`` pass (with ``inner`` false, ``S_q`` is still read off the counts, the inner
    boxes' included), so a box every pose of which satisfies all but at most ``q_max``
    readings (and lies in the room) is kept as an inner box instead of being bisected down to
    ``eps``; and no box is cut across an axis along which no visible wall changes
    (:mod:`intervals.sonar.idle`): where the set is large by nature (the sensors out of reach
    of every wall, or their echoes lost, constrain nothing; a strip along one wall) it is held
    by a few large boxes. Never a looser set from the first (an inner box lies in the set);
    the second only chooses where to cut. ``tests_per_box``: with ``max_boxes``, SIVIA tests
    at most this many times ``max_boxes`` boxes (default :data:`TESTS_PER_BOX`).
    """
    if not (isinstance(q_max, (int, np.integer)) and 0 <= q_max <= scan.belt.count):
        raise IntervalError(f"q_max must be an integer in [0, {scan.belt.count}], got {q_max!r}")
    _checked_budget(max_boxes)
    boxes = _pose_boxes(initial, "initial pose boxes")
    scale = pose_scale(heading_scale_m_per_rad)
    local = scan.restricted_to(boxes)
    widest, rejects, merged, held = _pave(
        local,
        boxes,
        eps,
        q_max,
        scale,
        inner or _checked_whole_boxes(whole_boxes),
        splits_per_level,
        uses_ray_test(ray_test, scan.belt),
        max_boxes,
        max_kept,
        None if within is None or len(within) > MAX_WITHIN_REGIONS else within,
        _checked_contract(contract),
        _checked_rounds(shave_rounds),
        _checked_levels(tighten_levels),
        whole_boxes,
        float(tests_per_box),
        _checked_tighten_tests(tighten_max_tested),
    )
    if widest.is_empty:
        return GomneResult(widest, None, None, merged)
    if inner:
        for q in range(q_max):
            minimal = localize(
                scan,
                widest.outer,
                eps,
                q,
                heading_scale_m_per_rad,
                inner,
                ray_test=ray_test,
                max_boxes=max_boxes,
                max_kept=max_kept,
                contract=contract,
                shave_rounds=shave_rounds,
                tighten_levels=tighten_levels,
                tighten_max_tested=tighten_max_tested,
            )
            if not minimal.is_empty:
                break
        else:
            q, minimal = q_max, widest
    else:
        # Every box of S_qmax is then a boundary box no wider than eps that passed the
        # in-room test: SIVIA at q < q_max on them would keep exactly those rejected by at most
        # q sensors, so the reject counts of the q_max pass give every S_q without a new pass.
        # With whole_boxes, an inner box of S_qmax rejected by at most q sensors is a box S_q
        # does not reject: kept in S_q's cover (as a boundary box when q < q_max).
        q = int(min(np.concatenate([rejects, held]).min(), q_max))
        if q == q_max:
            minimal = widest
        else:
            kept = np.concatenate([widest.inner[held <= q], widest.boundary[rejects <= q]])
            minimal = Subpaving(widest.inner[:0], kept, coarse=widest.coarse)
    return GomneResult(widest if guaranteed else minimal, q, q_max if guaranteed else q, merged)
