"""intervals: outward-rounded interval arithmetic on arrays, boxes, subpavings, SIVIA, IMAGESP,
and the sonar-cone inclusion tests.

Imports none of the other testbed packages: maps are segment arrays, readings are arrays.
"""
