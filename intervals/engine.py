"""The implementations of the compiled interval tests, a choice shared by the sonar box test
(:func:`intervals.sonar.sensor_verdicts`) and the ray test (:func:`intervals.rays.piece_rejections`)."""

from __future__ import annotations

from enum import StrEnum


class Engine(StrEnum):
    """How a box test runs: ``compiled`` (the numba kernels, the default) or ``numpy`` (the
    vectorised reference they are tested against: same operations, same sets)."""

    COMPILED = "compiled"
    NUMPY = "numpy"
