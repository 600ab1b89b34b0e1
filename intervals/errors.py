"""Errors raised by the interval package."""


class IntervalError(ValueError):
    """A precondition of an interval algorithm does not hold (``eps <= 0``, an empty box...)."""
