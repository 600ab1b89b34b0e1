"""Our SIVIA against codac 2's ``sivia`` (and ``pave`` with a separator) on the same set inversions.

    python benchmarks/intervals_vs_codac.py [--landmark-runs 5] [--tracking-runs 8] [--global-runs 0]
                                            [--belt-runs 8] [--repeats 3] [--seed 0]
                                            [--tighten-levels 0] [--write]

The default run takes about a minute; ``--global-runs 1`` adds the global case, where codac's
``sivia`` alone needs about three minutes.

(a) 2-D range-only localisation to four landmarks (the corners of a 10 m square), readings
with errors bounded by 0.1 m, initial box ``[-5, 15]^2``, ``eps = 0.01`` m. Ours: SIVIA with a
natural interval-arithmetic test (:mod:`intervals.interval`); codac: ``sivia`` of the vector
function of the four distances.

(b) 3-D pose ``(x, y, theta)`` in the ``hall`` map from the 16 range readings of the default
sonar belt taken along rays (the sonar model with a zero half-aperture), ``d_max`` 100 m so
that every ray meets a wall, errors bounded by ``0.02 m + 1 %``. Neither side takes a zero
half-aperture (``robotsim.sensors.sonar.cone_distances`` and ``intervals.sonar.scan.SonarBelt``
both require ``half_aperture_rad > 0``), so the readings are simulated and inverted by ours
with a cone of half-aperture :data:`RAY_HALF_APERTURE_RAD` (1e-6 rad: it departs from the ray by
at most 1e-5 m within 10 m). Codac expresses the ray model as an analytic function: for
sensor ``i`` at ``s(p) = (x, y) + R(theta) m_i`` pointing along ``u = (cos, sin)(theta +
alpha_i)``, segment ``j`` (``a + t e``) is met at distance ``lambda = det(a - s, e) / det(u, e)``
with ``t = det(a - s, u) / det(u, e)``; the reading is ``min_j chi(max(-lambda, -t, t - 1),
lambda, 1000)`` (``chi(c, a, b)`` is ``a`` where ``c <= 0``, else ``b``). Tracking: prior box
+-0.5 m, +-0.2 rad about a point within 0.25 m / 0.1 rad of the truth, ``eps`` 0.04 (not
0.05: the prior's heading width 0.4 rad halves to exactly 0.05, where the two libraries' ``<=``
and ``>`` tests round differently and keep boxes of different sizes); global: the whole hall,
heading ``[-pi, pi]``, ``eps`` 0.05. Same problem on both sides: no in-room test for ours (codac has none),
widths unscaled (heading scale 1 m/rad, as codac's ``max_diam``), all 16 sensors.

Ours in (b) three times, all ``intervals.localize.localize``: with the sonar box test alone
(``ray_test=False, contract=False``), "ours + ray test" (``ray_test=True``, what ``localize`` does by
default for cones this thin, ``contract=False``), and "ours + contractor" (both on: ``localize``'s
default; every SIVIA frontier contracted by :mod:`intervals.sonar.contractor` and the boxes kept
shaved, compared with codac's ``pave``, the contractor formulation: issue 13's target is a volume at
most codac's at least 3x faster); with ``--tighten-levels L`` also "ours + tightened", the same
with the kept boxes refined ``L`` bisections below ``eps`` (:mod:`intervals.tighten`).
The ray test: the sonar test, then on the boxes it would keep the ray test of
:mod:`intervals.sonar.rays` (the heading kept as one variable, boxes cut into
``intervals.sonar.rays.DEFAULT_PIECES`` heading pieces, a box rejected when every piece is rejected
by some sensor). The last table measures that combination on
the real belt (half-aperture 12.5 deg, ``d_max`` 3 m) and on narrower cones in tracking
epochs, to show where it pays (``--belt-runs``).

Named ``intervals_vs_codac.py``, not ``intervals.py``: run as a script, a file ``intervals.py`` in
``benchmarks/`` would shadow the ``intervals`` package (the script's folder comes first on
``sys.path``).

Both bisect boxes whose largest width exceeds ``eps`` and keep the undecided ones below; the
outer set is the union of inner and undecided boxes. Reported: wall time (best of
``--repeats``; codac ``sivia`` and ``pave`` run once on (b), they take seconds), the ratio
codac / ours, the outer volumes and their ratio ours / codac. Target (issue 7): at least 3x
faster than codac at an outer volume at most 1.25x codac's. Codac's ``pave`` with
``SepInverse`` (contractors, not bisection alone) is shown for reference. Every set must
contain the truth: the script exits 1 otherwise. ``--write`` updates this section of
``BENCHMARKS.md``.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from functools import partial

import codac
import numpy as np
from _common import best_seconds, machine_line, markdown_table, timed, write_section

from intervals import interval as ia
from intervals.boxes import contains_points, volume
from intervals.localize import localize
from intervals.sivia import INSIDE, OUTSIDE, UNDECIDED, sivia
from intervals.sonar import rays
from intervals.sonar.cone import sensor_verdicts
from intervals.sonar.scan import SonarBelt, SonarScan
from robotsim.maps import builtin_map, point_segment_distance
from robotsim.sensors.sonar import SonarBeltParams, cone_distances

SECTION = "Peer comparison: SIVIA against codac (issue 7)"
LANDMARKS_M = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]])
RANGE_ERROR_M = 0.1
LANDMARK_BOX = np.array([[-5.0, 15.0], [-5.0, 15.0]])
LANDMARK_EPS_M = 0.01
RAY_HALF_APERTURE_RAD = 1e-6
RAY_D_MAX_M = 100.0
NO_HIT_M = 1e3
"""Stand-in distance of a ray that misses a segment in codac's function (above every reading)."""
TRACKING_EPS = 0.04
GLOBAL_EPS = 0.05
TRACKING_HALF = np.array([0.5, 0.5, 0.2])
BELT_EPS = 0.05
BELT_HALF_APERTURES_RAD = (float(np.deg2rad(12.5)), 0.1, 0.05, 0.03, 0.003)
"""The default belt's half-aperture first, then narrower cones (see :func:`run_belt_case`)."""
SPLITS_PER_LEVEL = 3
"""Bisections per SIVIA level on our side (as ``intervals.localize.localize``): fewer, larger
numpy passes; the boxes kept are the same size."""


# ------------------------------------------------------------------------------ codac glue


def to_codac_box(box: np.ndarray) -> codac.IntervalVector:
    """Our box ``(d, 2)`` as a codac ``IntervalVector``."""
    return codac.IntervalVector([[float(lo), float(hi)] for lo, hi in box])


def codac_outer(paving) -> np.ndarray:
    """The outer boxes ``(N, d, 2)`` of a codac ``PavingInOut`` (inner and undecided leaves)."""
    boxes = paving.boxes(codac.PavingInOut.outer)
    if not boxes:
        return np.zeros((0, paving.tree().hull().size(), 2))
    return np.array([[[b[i].lb(), b[i].ub()] for i in range(b.size())] for b in boxes])


def vector_function(variable, components: list) -> codac.AnalyticFunction:
    """A codac vector function of scalar expressions.

    ``AnalyticFunction(args, [e_1, ..., e_k])`` crashes (segmentation fault) in codac 2.1.2 for
    more than 10 components, and ``vec`` takes at most 10; a sum of ``e_i`` times unit vectors
    builds the same function (``0 * [a, b] = 0`` exactly, so the enclosure is unchanged).
    """
    total = None
    for i, component in enumerate(components):
        unit = [0.0] * len(components)
        unit[i] = 1.0
        term = component * codac.Vector(unit)
        total = term if total is None else total + term
    return codac.AnalyticFunction([variable], total)


# --------------------------------------------------------------------- (a) range-only, 2-D


def range_test(ranges_m: np.ndarray):
    """Our SIVIA test for ``|p - L_i| in ranges_m[i]`` (4 landmarks), natural interval form."""
    lx, ly = ia.interval(LANDMARKS_M[:, 0]), ia.interval(LANDMARKS_M[:, 1])

    def test(boxes: np.ndarray) -> np.ndarray:
        dist = ia.sqrt(
            ia.add(ia.sqr(ia.sub(boxes[:, None, 0], lx)), ia.sqr(ia.sub(boxes[:, None, 1], ly)))
        )
        out = np.any((dist[..., 1] < ranges_m[:, 0]) | (dist[..., 0] > ranges_m[:, 1]), axis=1)
        inside = np.all((dist[..., 0] >= ranges_m[:, 0]) & (dist[..., 1] <= ranges_m[:, 1]), axis=1)
        return np.where(out, OUTSIDE, np.where(inside, INSIDE, UNDECIDED)).astype(np.int8)

    return test


def codac_range_function() -> codac.AnalyticFunction:
    """The four distances ``(2,) -> (4,)`` as a codac function."""
    p = codac.VectorVar(2)
    return codac.AnalyticFunction(
        [p],
        [
            codac.sqrt(codac.sqr(p[0] - float(lx)) + codac.sqr(p[1] - float(ly)))
            for lx, ly in LANDMARKS_M
        ],
    )


# ------------------------------------------------------------------- (b) rays in the hall


def ray_distance_function(segments: np.ndarray, params) -> codac.AnalyticFunction:
    """Codac's ``(x, y, theta) -> (k,)`` distances along the sensors' rays to the nearest segment."""
    pose = codac.VectorVar(3)
    x, y, theta = pose[0], pose[1], pose[2]
    readings = []
    for (mx, my), alpha in zip(params.mount_xy, params.mount_angle_rad, strict=True):
        radius, beta = float(np.hypot(mx, my)), float(np.arctan2(my, mx))
        sx, sy = x + radius * codac.cos(theta + beta), y + radius * codac.sin(theta + beta)
        ux, uy = codac.cos(theta + float(alpha)), codac.sin(theta + float(alpha))
        nearest = None
        for (ax, ay), (bx, by) in segments:
            ex, ey = float(bx - ax), float(by - ay)
            wx, wy = float(ax) - sx, float(ay) - sy
            det = ux * ey - uy * ex
            lam, t = (wx * ey - wy * ex) / det, (wx * uy - wy * ux) / det
            hit = codac.chi(codac.max(codac.max(-lam, -t), t - 1.0), lam, NO_HIT_M)
            nearest = hit if nearest is None else codac.min(nearest, hit)
        readings.append(nearest)
    return vector_function(pose, readings)


def ray_params() -> SonarBeltParams:
    """The default belt as (nearly) a ray sensor with an unbounded range (see the docstring)."""
    return dataclasses.replace(
        SonarBeltParams.default_belt(), half_aperture_rad=RAY_HALF_APERTURE_RAD, d_max_m=RAY_D_MAX_M
    )


def random_poses(segment_map, count: int, rng: np.random.Generator) -> np.ndarray:
    """``(count, 3)`` poses at least 0.3 m from every wall, inside the hall's bounds."""
    b = segment_map.bounds
    poses = []
    while len(poses) < count:
        p = np.array([*rng.uniform(b[:, 0], b[:, 1]), rng.uniform(-np.pi, np.pi)])
        seg = segment_map.segments
        if np.min(point_segment_distance(p[None, :2], seg[:, 0], seg[:, 1])) >= 0.3:
            poses.append(p)
    return np.array(poses)


def ray_readings(
    segments: np.ndarray, params, truth: np.ndarray, rng: np.random.Generator
) -> np.ndarray:
    """Readings ``(k,)``: true distances plus errors within 90 % of the bound (the 10 % margin
    covers the 1e-6 rad difference between our thin cone and codac's ray)."""
    d = cone_distances(
        truth, segments, params.mount_xy, params.mount_angle_rad, params.half_aperture_rad
    )
    bound = params.error_abs_bound_m + params.error_rel_bound * d
    return d + rng.uniform(-0.9, 0.9, d.shape) * bound


# ---------------------------------------------------------------------------- the runner


@dataclasses.dataclass
class Outcome:
    """One solver on one instance: seconds, outer volume, boxes, truth kept."""

    seconds: float
    outer: np.ndarray

    @property
    def volume(self) -> float:
        return volume(self.outer)

    @property
    def boxes(self) -> int:
        return self.outer.shape[0]

    def keeps(self, truth: np.ndarray) -> bool:
        return bool(np.any(contains_points(self.outer, truth[None])))


def ours(run, repeats: int) -> Outcome:
    paving = run()
    return Outcome(best_seconds(run, repeats), paving.outer)


def theirs(run, repeats: int) -> Outcome:
    paving, seconds = timed(run)
    if repeats > 1:
        seconds = min(seconds, best_seconds(run, repeats - 1))
    return Outcome(seconds, codac_outer(paving))


def cross_check(
    mine: Outcome,
    codac_sivia: Outcome,
    f: codac.AnalyticFunction,
    y: codac.IntervalVector,
    scan: SonarScan,
) -> np.ndarray:
    """Each side's box test on the other's outer boxes (boxes of the same size, so a rejection
    shows a tighter test, not a finer bisection). Returns counts ``(4,)``: our boxes codac's
    test rejects because some ray certainly meets a wall nearer than the reading, or only
    farther; codac's boxes our test rejects, and ours with the ray test (as
    ``localize(..., ray_test=True)``); our boxes."""
    nearer = farther = 0
    for box in mine.outer:
        image = f.eval(to_codac_box(box))
        misses = [i for i in range(y.size()) if not image[i].intersects(y[i])]
        nearer += any(image[i].ub() < y[i].lb() for i in misses)
        farther += bool(misses) and not any(image[i].ub() < y[i].lb() for i in misses)
    ours_rejects = ray_rejects = 0
    if codac_sivia.boxes:
        reject, _ = sensor_verdicts(codac_sivia.outer, scan, inner=False)
        ours_rejects = int(np.count_nonzero(reject.any(axis=1)))
        ray_rejects = int(
            np.count_nonzero(
                rays.joint_rejections(codac_sivia.outer, scan, 0, rays.DEFAULT_PIECES, reject)
            )
        )
    return np.array([nearer, farther, ours_rejects, ray_rejects, mine.boxes])


def landmark_instances(count: int, rng: np.random.Generator):
    for _ in range(count):
        truth = rng.uniform(1.0, 9.0, 2)
        d = np.hypot(*(LANDMARKS_M - truth).T)
        m = d + rng.uniform(-1.0, 1.0, 4) * RANGE_ERROR_M
        yield truth, np.stack([m - RANGE_ERROR_M, m + RANGE_ERROR_M], axis=-1)


def codac_pave(x0, f, y, eps: float):
    """Codac's paver on the separator of ``f^-1(y)`` over ``x0`` (the separator built inside,
    so that its construction is timed with the paving)."""
    return codac.pave(x0, codac.SepInverse(f, y), eps)


def run_case_a(count: int, repeats: int, rng: np.random.Generator) -> list[dict]:
    f = codac_range_function()
    x0 = to_codac_box(LANDMARK_BOX)
    results = []
    for truth, ranges in landmark_instances(count, rng):
        y = codac.IntervalVector([[float(lo), float(hi)] for lo, hi in ranges])
        results.append(
            {
                "truth": truth,
                "ours": ours(
                    partial(
                        sivia,
                        range_test(ranges),
                        LANDMARK_BOX,
                        LANDMARK_EPS_M,
                        splits_per_level=SPLITS_PER_LEVEL,
                    ),
                    repeats,
                ),
                "codac sivia": theirs(partial(codac.sivia, x0, f, y, LANDMARK_EPS_M), repeats),
                "codac pave": theirs(partial(codac_pave, x0, f, y, LANDMARK_EPS_M), repeats),
            }
        )
    return results


def run_case_b(
    kind: str,
    count: int,
    eps: float,
    repeats: int,
    rng: np.random.Generator,
    f: codac.AnalyticFunction,
    tighten_levels: int = 0,
) -> list[dict]:
    hall = builtin_map("hall")
    params = ray_params()
    belt = SonarBelt.from_params(params, echoes_never_lost=True)
    b = hall.bounds
    results = []
    for truth in random_poses(hall, count, rng):
        scan = SonarScan(
            hall.segments, belt, ray_readings(hall.segments, params, truth, rng), boundary=None
        )
        if kind == "tracking":
            centre = truth + rng.uniform(-1.0, 1.0, 3) * np.array([0.25, 0.25, 0.1])
            prior = np.stack([centre - TRACKING_HALF, centre + TRACKING_HALF], axis=-1)
        else:
            prior = np.array([b[0], b[1], [-np.pi, np.pi]])
        x0, y = to_codac_box(prior), to_codac_box(scan.ranges)
        result = {
            "truth": truth,
            "ours": ours(
                partial(
                    localize,
                    scan,
                    prior,
                    eps,
                    heading_scale_m_per_rad=1.0,
                    splits_per_level=SPLITS_PER_LEVEL,
                    ray_test=False,
                    contract=False,
                ),
                repeats,
            ),
            "codac sivia": theirs(partial(codac.sivia, x0, f, y, eps), 1),
            "codac pave": theirs(partial(codac_pave, x0, f, y, eps), 1),
            "ours + ray test": ours(
                partial(
                    localize,
                    scan,
                    prior,
                    eps,
                    heading_scale_m_per_rad=1.0,
                    splits_per_level=SPLITS_PER_LEVEL,
                    ray_test=True,
                    contract=False,
                ),
                repeats,
            ),
            "ours + contractor": ours(
                partial(
                    localize,
                    scan,
                    prior,
                    eps,
                    heading_scale_m_per_rad=1.0,
                    splits_per_level=SPLITS_PER_LEVEL,
                    ray_test=True,
                    contract=True,
                ),
                repeats,
            ),
        }
        if tighten_levels:
            result["ours + tightened"] = ours(
                partial(
                    localize,
                    scan,
                    prior,
                    eps,
                    heading_scale_m_per_rad=1.0,
                    splits_per_level=SPLITS_PER_LEVEL,
                    ray_test=True,
                    contract=True,
                    tighten_levels=tighten_levels,
                ),
                repeats,
            )
        result["cross"] = cross_check(
            result["ours"], result["codac sivia"], f, y, scan.restricted_to(prior)
        )
        results.append(result)
    return results


def run_belt_case(count: int, repeats: int, rng: np.random.Generator) -> list[list[str]]:
    """The ray test on the real belt (:meth:`SonarBeltParams.default_belt`, d_max 3 m) in
    tracking epochs, and at narrower half-apertures: rows of median times and volumes of our
    SIVIA alone and with the ray test (same scans, prior as (b) tracking, eps
    :data:`BELT_EPS`, no in-room test on either side)."""
    hall = builtin_map("hall")
    truths = random_poses(hall, count, rng)
    rows = []
    for gamma in BELT_HALF_APERTURES_RAD:
        params = SonarBeltParams.default_belt(half_aperture_rad=gamma)
        belt = SonarBelt.from_params(params, echoes_never_lost=True)
        alone, with_rays = [], []
        for truth in truths:
            d = cone_distances(truth, hall.segments, params.mount_xy, params.mount_angle_rad, gamma)
            bound = params.error_abs_bound_m + params.error_rel_bound * np.where(
                np.isfinite(d), d, 0.0
            )
            readings = np.where(
                d > params.d_max_m, np.inf, np.maximum(d + rng.uniform(-1, 1, d.shape) * bound, 0)
            )
            scan = SonarScan(hall.segments, belt, readings)
            centre = truth + rng.uniform(-1.0, 1.0, 3) * np.array([0.25, 0.25, 0.1])
            prior = np.stack([centre - TRACKING_HALF, centre + TRACKING_HALF], axis=-1)
            alone.append(
                ours(
                    partial(
                        localize,
                        scan,
                        prior,
                        BELT_EPS,
                        heading_scale_m_per_rad=1.0,
                        splits_per_level=SPLITS_PER_LEVEL,
                        ray_test=False,
                        contract=False,
                    ),
                    repeats,
                )
            )
            with_rays.append(
                ours(
                    partial(
                        localize,
                        scan,
                        prior,
                        BELT_EPS,
                        heading_scale_m_per_rad=1.0,
                        splits_per_level=SPLITS_PER_LEVEL,
                        ray_test=True,
                        contract=False,
                    ),
                    repeats,
                )
            )
            if not (alone[-1].keeps(truth) and with_rays[-1].keeps(truth)):
                raise SystemExit("FAILED: a set lost the truth (real belt)")
        ratio = np.median([b.volume / a.volume for a, b in zip(alone, with_rays, strict=True)])
        smaller = sum(b.volume < a.volume for a, b in zip(alone, with_rays, strict=True))
        rows.append(
            [
                f"{gamma:.3g} rad ({np.degrees(gamma):.1f} deg)",
                str(count),
                f"{np.median([o.seconds for o in alone]) * 1e3:.1f}",
                f"{np.median([o.seconds for o in with_rays]) * 1e3:.1f}",
                f"{np.median([o.volume for o in alone]):.3g}",
                f"{np.median([o.volume for o in with_rays]):.3g}",
                f"{ratio:.2f}",
                f"{smaller} / {count}",
            ]
        )
    return rows


BELT_HEADER = [
    "belt half-aperture",
    "epochs",
    "ours ms",
    "ours + ray test ms",
    "ours outer volume",
    "ours + ray test outer volume",
    "volume ratio (with / without)",
    "epochs where smaller",
]


def summarise(label: str, results: list[dict]) -> tuple[list[str], bool]:
    """A table row (medians over the instances, with the target's verdict) and whether every
    set kept the truth."""

    def med(solver: str, field: str) -> float:
        return float(np.median([getattr(r[solver], field) for r in results]))

    time_ratio = float(np.median([r["codac sivia"].seconds / r["ours"].seconds for r in results]))
    volume_ratio = float(np.median([r["ours"].volume / r["codac sivia"].volume for r in results]))
    kept = all(r[solver].keeps(r["truth"]) for r in results for solver in SOLVERS if solver in r)
    met = time_ratio >= 3.0 and volume_ratio <= 1.25
    row = [
        label,
        str(len(results)),
        f"{med('ours', 'seconds') * 1e3:.1f}",
        f"{med('codac sivia', 'seconds') * 1e3:.1f}",
        f"{med('codac pave', 'seconds') * 1e3:.1f}",
        f"{time_ratio:.1f}x",
        f"{med('ours', 'volume'):.3g}",
        f"{med('codac sivia', 'volume'):.3g}",
        f"{med('codac pave', 'volume'):.3g}",
        f"{volume_ratio:.2f}",
        f"{med('ours', 'boxes'):.0f} / {med('codac sivia', 'boxes'):.0f}",
        "met" if met else "MISSED",
        "yes" if kept else "NO",
    ]
    if "ours + ray test" in results[0]:
        ray_volume = float(
            np.median([r["ours + ray test"].volume / r["codac sivia"].volume for r in results])
        )
        ray_time = float(
            np.median([r["codac sivia"].seconds / r["ours + ray test"].seconds for r in results])
        )
        ray_met = ray_time >= 3.0 and ray_volume <= 1.25
        row += [
            f"{med('ours + ray test', 'seconds') * 1e3:.1f}",
            f"{ray_time:.0f}x",
            f"{ray_volume:.2f}",
            f"{med('ours + ray test', 'boxes'):.0f}",
            "met" if ray_met else "MISSED",
        ]
    else:
        row += ["-"] * 5
    for solver in ("ours + contractor", "ours + tightened"):
        if solver not in results[0]:
            row += ["-"] * 6
            continue
        rows = [r[solver] for r in results]
        vs_sivia = np.median(
            [o.volume / r["codac sivia"].volume for o, r in zip(rows, results, strict=True)]
        )
        vs_pave = np.median(
            [o.volume / r["codac pave"].volume for o, r in zip(rows, results, strict=True)]
        )
        faster = np.median(
            [r["codac pave"].seconds / o.seconds for o, r in zip(rows, results, strict=True)]
        )
        row += [
            f"{med(solver, 'seconds') * 1e3:.1f}",
            f"{vs_sivia:.2f}",
            f"{vs_pave:.2f}",
            f"{faster:.0f}x",
            f"{med(solver, 'boxes'):.0f}",
            "met" if vs_pave <= 1.0 and faster >= 3.0 else "MISSED",
        ]
    return row, kept


SOLVERS = (
    "ours",
    "codac sivia",
    "codac pave",
    "ours + ray test",
    "ours + contractor",
    "ours + tightened",
)
HEADER = [
    "case",
    "runs",
    "ours ms",
    "codac sivia ms",
    "codac pave ms",
    "time ratio codac sivia / ours",
    "ours outer volume",
    "codac sivia outer volume",
    "codac pave outer volume",
    "volume ratio ours / codac sivia",
    "boxes ours / codac sivia",
    "target",
    "truth in every set",
    "ours + ray test (intervals.sonar.rays) ms",
    "its time ratio",
    "its volume ratio",
    "its boxes",
    "its target",
    "ours + contractor (intervals.sonar.contractor, with the ray test) ms",
    "its volume ratio / codac sivia",
    "its volume ratio / codac pave",
    "time ratio codac pave / it",
    "its boxes",
    "its target (issue 13: volume <= codac pave's, >= 3x faster)",
    "ours + tightened (intervals.tighten, --tighten-levels, on the contractor's set) ms",
    "its volume ratio / codac sivia",
    "its volume ratio / codac pave",
    "time ratio codac pave / it",
    "its boxes",
    "its target (issue 13)",
]
CROSS_HEADER = [
    "case",
    "our outer boxes",
    "of them rejected by codac's test (a ray surely meets a wall nearer / only farther)",
    "codac sivia outer boxes",
    "of them rejected by our test",
    "of them rejected by ours + ray test",
]

ANALYSIS = """\
Findings (causes measured with the cross-check above and with timings of the parts):

- (a) Our SIVIA is about 3 times faster than codac's ``sivia`` at the same outer volume. Codac
  evaluates one box at a time in C++ (natural and centred forms, so a Jacobian per box); ours
  evaluates each level's boxes in one numpy pass, with 3 bisections per level
  (``splits_per_level=3``, as ``intervals.localize.localize``). With one bisection per level ours
  takes about 5 ms here (1.7x only): the fixed cost of the test's ~25 numpy calls per level is
  most of the time, so the level count, not the box count, sets the speed.
- (b) Our sonar test alone is about a thousand (tracking) to ten thousand (global) times faster
  (codac evaluates a 16 x 12-term expression with its centred form per box, in minutes for the
  global case), but its outer set is 1.4 to 3.5 times codac's ``sivia`` set: MISSED. At equal
  box size codac's test rejects about half of its boxes, mostly because a wall is certainly on
  the ray nearer than the reading. Cause, in ``intervals/sonar/cone.py``: its tests are built for
  a wide cone. The free-space test needs a direction in the cone for every heading of the box
  (heading width below ``2 gamma``), never the case for ``gamma = 1e-6`` rad, and the hit test
  lets the sensor position range over its box independently of the direction.
- With the ray test of ``intervals/sonar/rays.py`` (the heading as one variable in the ray-segment
  meeting, boxes cut into 4 heading pieces and rejected when every piece is rejected by some
  sensor of either test, applied to the boxes no wider than ``eps`` that the sonar test keeps;
  numba kernel) the target is met: tracking volume ratio 0.61 at about 300x, global 1.00 (the
  same 2 boxes as codac) at thousands of times. On codac's own boxes it rejects 24 of 74 (the
  sonar test alone: 6), so at equal box size it is now the tighter test. Without the pieces
  (one piece, per-sensor rejection) the global set keeps a third box: every one of the 16
  readings is, alone, consistent with some pose of that box (checked by sampling 400,000
  poses), so no per-sensor test can reject it; the pieces do, since different sensors reject
  different heading pieces. The ray free-space test changed one tracking set of 8 (7 boxes to
  5) and no global one; with the cone's edge rays it is what makes the test pay on the real
  belt.
- Real belt (last table): the ray test also pays at 12.5 deg (median volume 0.90 of the sonar
  test's, smaller in 7 of 8 epochs) and more on narrower cones (0.74 at 0.1 rad, 0.37 to 0.67
  below), for about 5 ms more per epoch (7 ms against the compiled sonar test's 2 ms; the
  numpy reference of the ray test: about 13 ms more). Hence ``intervals.localize.localize`` and
  ``gomne`` apply it by default only to cones of half-aperture up to 0.1 rad
  (``ray_test=None``); on the default belt it is an opt-in (``ray_test=True``), which would
  cost the pipeline about 3 s per 600 s.
- Codac's ``pave`` with ``SepInverse`` (contractors: boxes are shrunk, not only kept or
  dropped) gives in (b) sets 5 to 20 times smaller than either ``sivia``, in 0.5 to 1.6 times
  codac's ``sivia`` time (in (a) 10 % smaller and 3 times slower than its ``sivia``); it is a
  different algorithm and outside the target. Contracting the kept boxes
  (e.g. one forward-backward pass of the distance constraint, or HC4 on the range equations in
  (a)) is how our outer sets would reach it.
"""


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--landmark-runs", type=int, default=5)
    parser.add_argument("--tracking-runs", type=int, default=8)
    parser.add_argument("--global-runs", type=int, default=0)
    parser.add_argument("--belt-runs", type=int, default=8)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--tighten-levels",
        type=int,
        default=0,
        help="also run ours + contractor with the kept boxes tightened this many levels (0: not)",
    )
    parser.add_argument("--write", action="store_true", help="update this section of BENCHMARKS.md")
    args = parser.parse_args(argv)
    if (
        min(args.landmark_runs, args.tracking_runs, args.global_runs, args.belt_runs) < 0
        or args.repeats < 1
    ):
        parser.error("run counts must be >= 0 and --repeats >= 1")
    codac.set_nb_threads(1)  # one core each, as ours
    rng = np.random.default_rng(args.seed)
    hall = builtin_map("hall")
    f_rays, build_s = timed(lambda: ray_distance_function(hall.segments, ray_params()))
    cases = [
        (
            "(a) range-only, 4 landmarks, eps 0.01",
            lambda: run_case_a(args.landmark_runs, args.repeats, rng),
            args.landmark_runs,
        ),
        (
            f"(b) hall rays, tracking +-0.5 m +-0.2 rad, eps {TRACKING_EPS:g}",
            lambda: run_case_b(
                "tracking",
                args.tracking_runs,
                TRACKING_EPS,
                args.repeats,
                rng,
                f_rays,
                args.tighten_levels,
            ),
            args.tracking_runs,
        ),
        (
            f"(b) hall rays, global, eps {GLOBAL_EPS:g}",
            lambda: run_case_b(
                "global",
                args.global_runs,
                GLOBAL_EPS,
                args.repeats,
                rng,
                f_rays,
                args.tighten_levels,
            ),
            args.global_runs,
        ),
    ]
    rows, cross_rows, all_kept = [], [], True
    for label, run, count in cases:
        if count == 0:
            continue
        results = run()
        row, kept = summarise(label, results)
        rows.append(row)
        all_kept &= kept
        if "cross" in results[0]:
            nearer, farther, ours_rejects, ray_rejects, boxes = np.sum(
                [r["cross"] for r in results], axis=0
            )
            codac_boxes = sum(r["codac sivia"].boxes for r in results)
            cross_rows.append(
                [
                    label,
                    str(boxes),
                    f"{nearer + farther} ({nearer} / {farther})",
                    str(codac_boxes),
                    str(ours_rejects),
                    str(ray_rejects),
                ]
            )
        print(f"done: {label}", file=sys.stderr)
    table = markdown_table(HEADER, rows)
    cross = markdown_table(CROSS_HEADER, cross_rows) if cross_rows else ""
    belt = (
        markdown_table(BELT_HEADER, run_belt_case(args.belt_runs, args.repeats, rng))
        if args.belt_runs
        else ""
    )
    print(table)
    print()
    print(cross)
    print()
    print(belt)
    print(f"\n(codac's ray function: built in {build_s:.2f} s, not timed above)")
    if args.write:
        command = (
            f"python benchmarks/intervals_vs_codac.py --landmark-runs {args.landmark_runs} --tracking-runs "
            f"{args.tracking_runs} --global-runs {args.global_runs} --belt-runs {args.belt_runs} "
            f"--repeats {args.repeats} --seed {args.seed}"
            + (f" --tighten-levels {args.tighten_levels}" if args.tighten_levels else "")
        )
        write_section(
            SECTION,
            "\n\n".join(
                [
                    f"Machine: {machine_line('codac')}; codac on one thread.",
                    f"```sh\n{command}\n```",
                    "Figures are medians over the runs (times: best of the repeats for ours and case (a); one "
                    "run of codac on (b)). Problems and settings: the script's docstring.",
                    table,
                    "Each side's box test on the other's outer boxes (same box sizes, all runs summed): a "
                    "rejection means the other test is tighter on that box.",
                    cross,
                    "The ray test on the real belt and on narrower cones (tracking epochs in `hall`, "
                    "d_max 3 m, same scans with and without it):",
                    belt,
                    ANALYSIS,
                ]
            ),
        )
    if not all_kept:
        print("FAILED: a set lost the truth", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
