"""Numpy references of the compiled sonar box tests, for tests and benchmarks only.

Each module evaluates, on numpy arrays, the operations its compiled counterpart performs in
scalar loops, in the same order: :mod:`intervals.sonar.reference.cone` (the cone test of
:mod:`intervals.sonar.cone`, with the primitives of :mod:`intervals.sonar.reference.geometry`),
:mod:`intervals.sonar.reference.room` (:mod:`intervals.sonar.room`) and
:mod:`intervals.sonar.reference.rays` (:mod:`intervals.sonar.rays`). The tests compare them
verdict for verdict; the production path never imports them (tested), so it has one
implementation of each test, the kernel.

:func:`reference_box_tests` runs the production pipeline (:mod:`intervals.localize`, the
tracker) on the references instead, for the tests that compare whole pavings and the
benchmark that times the kernels against them.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator


@contextlib.contextmanager
def reference_box_tests() -> Iterator[None]:
    """Within the block, :mod:`intervals.localize` (hence the tracker) calls the numpy
    references instead of the kernels: the cone test, the in-room test and the ray test (the
    names it looks up at each call are replaced, and restored on exit; one thread at a time)."""
    import intervals.localize as localize
    from intervals.sonar import rays
    from intervals.sonar.reference import cone, room
    from intervals.sonar.reference import rays as reference_rays

    replaced = (
        (localize, "sensor_verdicts", cone.sensor_verdicts),
        (localize, "room_verdicts", room.room_verdicts),
        (rays, "piece_rejections", reference_rays.piece_rejections),
    )
    saved = [(module, name, getattr(module, name)) for module, name, _ in replaced]
    try:
        for module, name, reference in replaced:
            setattr(module, name, reference)
        yield
    finally:
        for module, name, original in saved:
            setattr(module, name, original)
