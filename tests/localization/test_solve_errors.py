"""``localization.linalg.solve`` on a singular system: a NumericalError, never a raw LinAlgError
(issue 12, item 8)."""

from __future__ import annotations

import numpy as np
import pytest

from localization.errors import EstimationError, NumericalError
from localization.linalg import solve


@pytest.mark.parametrize(
    "matrix",
    [np.zeros((3, 3)), np.array([[1.0, 2.0], [2.0, 4.0]]), np.zeros((4, 2, 2))],
)
def test_a_singular_system_raises_a_numerical_error(matrix):
    rhs = np.ones((*matrix.shape[:-1], 1))
    with pytest.raises(NumericalError, match="singular") as failure:
        solve(matrix, rhs)
    assert isinstance(failure.value, EstimationError)
    assert not isinstance(failure.value, np.linalg.LinAlgError)


def test_a_regular_system_is_solved():
    matrix = np.array([[4.0, 1.0], [1.0, 3.0]])
    rhs = np.array([[1.0], [2.0]])
    np.testing.assert_allclose(matrix @ solve(matrix, rhs), rhs, rtol=1e-14)
