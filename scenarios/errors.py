"""The two kinds of failure the ``robotsim`` command tells apart.

- :class:`ScenarioError`: a user's mistake (a scenario file, a map, an option, an output
  path that cannot be used). It names the file, the key and the reason; the CLI prints it on
  one line and exits with status 2.
- :class:`InternalError`: a failure of the tool itself (a numerical breakdown on input that
  passed validation, a recording that does not read back). The CLI exits with status 3,
  says on one line that it is a defect of robotsim, and keeps the traceback (``--debug``
  prints it; otherwise it goes to a crash file whose path is printed).

Every exception the CLI does not know as a user's mistake is treated as internal.
"""

from __future__ import annotations

from pathlib import Path


class ScenarioError(ValueError):
    """A scenario (or its map, an option, an output path) that cannot be run: the user's to fix.

    Formats as ``<file>: <key>: <reason>`` so the CLI can print it on one line.
    """

    def __init__(self, source: str | Path | None, key: str | None, reason: str):
        self.source = None if source is None else str(source)
        self.key = key
        self.reason = reason
        parts = [p for p in (self.source, key) if p]
        super().__init__(": ".join([*parts, reason]))


class InternalError(RuntimeError):
    """A defect of the tool: something that must not fail on validated input failed."""
