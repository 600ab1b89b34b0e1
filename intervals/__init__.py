"""intervals: outward-rounded interval arithmetic on arrays, boxes, subpavings, SIVIA, IMAGESP,
the sonar model on pose boxes (:mod:`intervals.sonar`), localisation from a scan
(:mod:`intervals.localize`) and the tracker (:mod:`intervals.tracker`).

Imports none of the other testbed packages: maps are segment arrays, readings are arrays.
"""
