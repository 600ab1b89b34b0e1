"""Errors raised by the interval package.

:class:`IntervalError` is a precondition of an interval algorithm that does not hold;
:class:`IntervalBudgetError`, its subclass, a paving that outgrew its box budget (the
precision asked for is too fine for the region searched). Under the ``robotsim`` command,
on a validated scenario, the first is a defect of the tool; the second is reported as the
scenario's ``estimation`` setting to change.
"""


class IntervalError(ValueError):
    """A precondition of an interval algorithm does not hold (``eps <= 0``, an empty box...)."""


class IntervalBudgetError(IntervalError):
    """A paving exceeded its budget of boxes (raise ``eps`` or shrink the initial box)."""
