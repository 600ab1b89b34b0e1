"""Both wrap_angle functions (and wrap_columns) keep headings in [-pi, pi), edges included."""

from __future__ import annotations

import math

import numpy as np
import pytest

from localization.linalg import wrap_angle as wrap_localization
from localization.linalg import wrap_columns
from robotsim.robot import wrap_angle as wrap_robotsim

#: Values at and just beside the edges of the range, and whole turns away from them.
EDGES = np.array(
    [
        -math.pi,
        math.pi,
        np.nextafter(-math.pi, -np.inf),  # (a + pi) % 2pi rounds up to 2pi: the old +pi
        np.nextafter(-math.pi, np.inf),
        np.nextafter(math.pi, -np.inf),
        np.nextafter(math.pi, np.inf),
        3.0 * math.pi,
        -3.0 * math.pi,
        np.nextafter(-3.0 * math.pi, -np.inf),
        0.0,
        -0.0,
        1e-300,
        -1e-300,
    ]
)


@pytest.mark.parametrize("wrap", [wrap_robotsim, wrap_localization])
def test_wrap_angle_stays_in_the_half_open_range_at_the_edges(wrap):
    wrapped = wrap(EDGES)
    assert np.all(wrapped >= -math.pi) and np.all(wrapped < math.pi)
    # the same direction: a whole number of turns away, to rounding
    turns = (EDGES - wrapped) / (2.0 * math.pi)
    np.testing.assert_allclose(turns, np.round(turns), atol=1e-12)
    # one scalar at a time gives the same numbers, as numpy floats
    for angle, expected in zip(EDGES, wrapped, strict=True):
        scalar = wrap(float(angle))
        assert np.ndim(scalar) == 0 and float(scalar) == expected
    assert wrap(np.nextafter(-math.pi, -np.inf)) == -math.pi


def test_wrap_columns_single_vector_and_batch_agree_at_the_edges():
    batch = np.column_stack([np.zeros_like(EDGES), EDGES])
    single = [wrap_columns(row.copy(), (1,))[1] for row in batch]
    wrapped = wrap_columns(batch.copy(), (1,))[:, 1]
    assert np.array_equal(single, wrapped)
    assert np.all(wrapped >= -math.pi) and np.all(wrapped < math.pi)
