r"""The cone test: sound per-sensor verdicts of the sonar cone model on pose boxes
(docs/models.md sections 3-4, paper 002 s. 3). The model and the reading intervals: :mod:`intervals.sonar.scan`.

Tests on a pose box ``[p] = [x] x [y] x [theta]`` for sensor ``i`` with ``[d_i] = [lo, hi]``.
Write ``S`` for a box enclosing ``{s_i(p) : p in [p]}``: ``[x] + |m_i| [c]`` etc., where
``[c]`` bounds ``cos`` over the arc ``[theta] + beta_i`` (its end values, or +-1 where the arc
passes an axis direction), then widened by ``SENSOR_BOX_MARGIN (1 + |m_i|)`` m (see below);
``Phi`` for the cone-direction interval ``[theta] + alpha_i + [-gamma, gamma]`` and ``Psi`` for
the directions in the cone for *every* ``theta`` of the box: ``[theta_hi + alpha_i - gamma,
theta_lo + alpha_i + gamma]`` (empty, i.e. not used, unless the box is narrower than
``2 gamma - 1e-9`` rad; ``width(Phi) < pi`` likewise only claimed with a ``1e-9`` rad margin).

* **Hit (data) test** (reject when it fails). If ``d_i(p) in [lo, hi]`` with ``hi`` finite,
  the nearest cone point ``P`` of some segment ``j`` satisfies ``P - s in W(Phi)`` (the wedge of
  directions ``Phi``, apex included) and ``|P - s| in [lo, hi]``. Relaxation (each step gives a
  superset, so rejection stays sound): let ``s`` range over ``S`` independently of the cone
  direction; then ``P`` lies in ``U = S + W(Phi)``, which, when ``width(Phi) < pi``, is contained
  in the two half-planes ``n_k . q >= min_{s in S} n_k . s`` (``n_k`` the inward normals of
  the wedge edges; for ``width(Phi) >= pi`` we use the whole plane). Clipping segment ``j`` to
  them gives a sub-segment ``seg'`` holding ``P``; hence ``dist(seg', S) <= |P - s| <= hi`` and
  ``max_{q in seg', s in S} |q - s| >= lo``. The box is rejected by sensor ``i`` when no segment
  passes both, evaluated with a lower bound of ``dist(seg', S)`` (``segment_box_gap``) and an
  upper bound of the maximum (attained at an end of ``seg'`` and a corner of ``S``).
* **Free-space test** (reject when it fires). If ``P`` on a segment lies in
  ``W(s, Psi)`` for every ``s in S`` (the half-planes ``n_k . P >= max_{s in S} n_k . s``, an
  intersection of wedges, exact) and ``|P - c| + r < lo`` with ``c, r`` the centre and
  half-diagonal of ``S`` (so ``|P - s| < lo`` for every ``s in S``), then for every pose of the
  box ``P`` is in the cone closer than ``lo``, so ``d_i(p) < lo``: the box is infeasible.
* **Inner acceptance** (optional). Every pose of the box satisfies sensor ``i`` when
  ``dist(seg'_j, S) >= lo`` for every segment (so ``d_i >= lo``) and some segment has a point
  as in the free-space test with ``|P - c| + r <= hi`` (so ``d_i <= hi``); for a no-echo reading
  the first condition with ``> d_max`` suffices.
* Only segments within ``reach`` of the hull of the sensor boxes take part (``reach`` = the
  largest ``hi`` of an echo, or ``d_max`` when no-echo readings are used): farther segments can
  neither be hit within ``hi`` nor be closer than any ``lo``.

The in-room test is in :mod:`intervals.sonar.room`, the q-relaxation that combines the
verdicts in :mod:`intervals.localize`; floating point (why every comparison keeps feasible
boxes) in :mod:`intervals.sonar.geometry`.

The sensor tests (and the in-room test) run in the compiled kernels of
:mod:`intervals.sonar.cone_kernel` (numba; one call per SIVIA level, scalar loops over boxes,
segments and sensors). Their reference, which the tests compare them with, is the vectorised
numpy code of :mod:`intervals.sonar.reference.cone` and :mod:`intervals.sonar.reference.room`,
outside the production path. The kernels evaluate the same formulas in the same order of
float64 operations (compiled without ``fastmath``: no fused multiply-adds, no reassociation),
with the same constants and biases, on the same outward-rounded reading intervals, mount
constants and ``cos``/``sin`` of the heading bounds (computed by numpy, :func:`heading_trig`,
and passed in), so their verdicts are the reference's bit for bit and everything above and in
:mod:`intervals.sonar.geometry` holds for both (the tests compare 36,000 random boxes, about
1.7 million per-sensor verdicts and 108,000 box verdicts: none differs). Had the kernel taken
``cos``/``sin`` from libm instead, the ulp or two by which they may differ from numpy's would
still lie inside the ``1e-15`` per component allowed in :mod:`intervals.sonar.geometry`.
"""

from __future__ import annotations

import numpy as np

from intervals import interval as ia
from intervals.boxes import as_boxes
from intervals.errors import IntervalError
from intervals.sonar import cone_kernel
from intervals.sonar.geometry import ANGLE_MARGIN_RAD, ARC_SLACK, GUARD_M, NEAR_SWITCH_M
from intervals.sonar.scan import SonarScan


def heading_trig(boxes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(cos, sin)`` ``(N, 2)`` of the heading bounds of boxes ``(N, 3, 2)``: the one source of
    these values for the kernels and the numpy reference (so they see the same directions)."""
    theta = boxes[:, 2]
    return np.cos(theta), np.sin(theta)


def sensor_verdicts(
    boxes, scan: SonarScan, inner: bool = True, validated: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """Per box and sensor: ``(reject (N, k), certain (N, k))`` bool arrays.

    ``reject``: the sensor's reading is inconsistent with every pose of the box (hit test fails
    or free-space test fires). ``certain``: the reading is consistent with every pose of the box
    (only computed when ``inner``; else all False). Ignored sensors never reject and are always
    certain (when ``inner``). See the module doc for the tests and their soundness. One call
    of :func:`intervals.sonar.cone_kernel.sensor_verdicts_into` for all boxes.
    ``validated``: ``boxes`` is already a checked float64 ``(N, 3, 2)`` array
    (:func:`intervals.boxes.as_boxes`, e.g. a SIVIA frontier), not checked again.
    """
    if not validated:
        boxes = as_boxes(boxes)
        if boxes.shape[1] != 3:
            raise IntervalError(f"sonar test: pose boxes must be (N, 3, 2), got {boxes.shape}")
    n, k = boxes.shape[0], scan.belt.count
    reject, certain = np.empty((n, k), dtype=bool), np.empty((n, k), dtype=bool)
    belt, boxes = scan.belt, np.ascontiguousarray(boxes)  # one compiled signature: C order
    assert scan.scene is not None
    grid = scan.scene.grid
    cone_kernel.sensor_verdicts_into(
        boxes,
        *heading_trig(boxes),
        scan.scene.segments,
        scan.allowed,
        grid.origin,
        grid.cell_m,
        np.array(grid.shape, dtype=np.int64),
        grid.starts,
        grid.members,
        scan.ranges,
        scan.kind,
        scan.reach_m,
        belt.kernel_table,
        belt.half_aperture_rad,
        belt.sensor_box_margin_m,
        GUARD_M,
        NEAR_SWITCH_M,
        ARC_SLACK,
        ANGLE_MARGIN_RAD,
        ia.TRIG_EXACT_LIMIT_RAD,
        bool(inner),
        reject,
        certain,
    )
    return reject, certain
