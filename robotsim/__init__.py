"""robotsim: the pymunk world, the differential-drive robot, path following and its sensors.

Imports none of the other testbed packages. Units are SI (metres, seconds, radians).
"""
