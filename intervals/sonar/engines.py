"""The implementations of the sonar box tests, one choice for all of them.

``compiled``: the numba kernels (:mod:`intervals.sonar.cone_kernel`, the kernel of
:mod:`intervals.sonar.rays`), the default; ``numpy``: the vectorised references they are
tested against (same operations, same verdicts, same sets).
"""

from __future__ import annotations

from enum import StrEnum


class Engine(StrEnum):
    """How a box test runs, accepted by the cone test
    (:func:`intervals.sonar.cone.sensor_verdicts`), the in-room test, the ray test
    (:func:`intervals.sonar.rays.piece_rejections`), :mod:`intervals.localize` and the
    tracker."""

    COMPILED = "compiled"
    NUMPY = "numpy"
