"""The borrowed views of ``localization.compiled.batch``: the memory they view, their types."""

from __future__ import annotations

import numba
import numpy as np
import pytest

from localization.compiled.batch import borrow, carve


@numba.njit
def _carve_and_write(buffer, start, rows, cols):
    """Carve ``(rows, cols)`` from ``buffer`` at ``start``; write row ``r`` col ``c`` as
    ``100 r + c`` through the view; return the end and a copy of the view."""
    view, end = carve(buffer, start, rows, cols)
    for r in range(rows):
        for c in range(cols):
            view[r, c] = 100.0 * r + c
    return end, view.copy()


def test_carve_views_the_buffer_as_reshape_would():
    buffer = np.full(20, -1.0)
    end, copied = _carve_and_write(buffer, 3, 4, 3)
    assert end == 15
    expected = 100.0 * np.arange(4)[:, None] + np.arange(3)
    np.testing.assert_array_equal(copied, expected)
    np.testing.assert_array_equal(buffer[3:15].reshape(4, 3), expected)  # written in place
    assert (buffer[:3] == -1.0).all() and (buffer[15:] == -1.0).all()


def test_carve_refuses_a_buffer_too_short():
    with pytest.raises(ValueError, match="too short"):
        _carve_and_write(np.zeros(10), 3, 4, 2)


@numba.njit
def _borrow_and_sum(values):
    view = borrow(values)
    view[0, 1] += 1.0  # writes through
    return view.sum(), view.shape, view.strides


def test_borrow_is_the_same_array():
    values = np.arange(12.0).reshape(3, 4)
    total, shape, strides = _borrow_and_sum(values)
    assert total == 67.0 and shape == (3, 4) and strides == values.strides
    assert values[0, 1] == 2.0
    strided = np.arange(24.0).reshape(3, 8)[:, ::2]  # any layout, strides kept
    assert _borrow_and_sum(strided)[2] == strided.strides
