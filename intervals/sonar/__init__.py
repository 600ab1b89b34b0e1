"""The sonar model on pose boxes: the scan model and the box tests.

* :mod:`intervals.sonar.scan`: the belt, the reading intervals, a run's scene (the map,
  validated once) and an epoch's scan;
* :mod:`intervals.sonar.geometry`: tolerances and the numpy geometric primitives;
* the box tests, each run by its compiled kernel: :mod:`intervals.sonar.cone` (hit and
  free-space tests of the cone, kernel in :mod:`intervals.sonar.cone_kernel`),
  :mod:`intervals.sonar.room` (in-room test) and :mod:`intervals.sonar.rays` (the ray test,
  heading kept as one variable);
* :mod:`intervals.sonar.contractor`: the contractor of pose boxes by the echoes (compiled),
  applied before the tests, and the shaving of the boxes kept;
* :mod:`intervals.sonar.reference`: the numpy references the kernels are tested against
  (tests and benchmarks only; nothing else imports it).

Paving, q-relaxation and GOMNE on top of these tests are in :mod:`intervals.localize`.
Dependencies go one way: geometry and the kernels, then scan, then the tests; nothing here
imports :mod:`intervals.localize` (but the references' switch of the pipeline,
:func:`intervals.sonar.reference.reference_box_tests`).
"""
