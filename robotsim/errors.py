"""Errors raised by the simulator for a user's mistake (bad map, impossible setting)."""


class RobotsimError(ValueError):
    """A simulator input a user can fix; the message says what and why."""


class MapError(RobotsimError):
    """A segment map that cannot be used (empty, non-finite, zero-length segment, unreadable)."""
