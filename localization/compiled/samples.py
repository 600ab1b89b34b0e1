"""The localiser's odometry samples appended in one compiled call (numba): the checks and the
copies of :meth:`localization.localizer.OnlineLocalizer.push_odometry_block`.

:func:`append_samples` checks each new sample (its time on the regular grid, a finite gyro
and accelerometer reading) and copies it into the localiser's buffers; it stops at the first
sample that fails and says which check failed. The buffers past the caller's count are free
space, so a refused block leaves the appended samples as they were.
"""

from __future__ import annotations

import math

import numba

#: What :func:`append_samples` found: every sample appended, or the check the first refused
#: sample failed.
APPENDED, OFF_GRID, GYRO_NOT_FINITE, ACCEL_NOT_FINITE = range(4)


@numba.njit(cache=True)
def append_samples(
    t_s,
    ticks,
    gyro_rad_s,
    accel_m_s2,
    count,
    first_t_s,
    dt_s,
    out_t_s,
    out_ticks,
    out_gyro,
    out_accel,
) -> tuple[int, int]:
    """Copy samples ``t_s (n,)``, ``ticks (n, 2)``, ``gyro_rad_s (n,)``, ``accel_m_s2 (n, 2)``
    into rows ``count..count + n - 1`` of the buffers ``out_*`` (room for them is the
    caller's).

    Sample ``k`` must lie within half a period of the grid time
    ``first_t_s + (count + k) dt_s`` (a NaN time does not) and have a finite gyro and
    accelerometer reading. Returns ``(APPENDED, n)``, or the failed check and ``k`` of the
    first sample refused (rows from ``count`` on may then hold copies: free space).
    """
    half_s = 0.5 * dt_s
    for k in range(t_s.shape[0]):
        row = count + k
        if not abs(t_s[k] - (first_t_s + row * dt_s)) <= half_s:
            return OFF_GRID, k
        if not math.isfinite(gyro_rad_s[k]):
            return GYRO_NOT_FINITE, k
        if not (math.isfinite(accel_m_s2[k, 0]) and math.isfinite(accel_m_s2[k, 1])):
            return ACCEL_NOT_FINITE, k
        out_t_s[row] = t_s[k]
        out_ticks[row, 0], out_ticks[row, 1] = ticks[k, 0], ticks[k, 1]
        out_gyro[row] = gyro_rad_s[k]
        out_accel[row, 0], out_accel[row, 1] = accel_m_s2[k, 0], accel_m_s2[k, 1]
    return APPENDED, t_s.shape[0]
