"""The user-facing error of a scenario file: it names the file, the key and the reason."""

from __future__ import annotations

from pathlib import Path


class ScenarioError(ValueError):
    """A scenario (or its map) that cannot be run.

    Formats as ``<file>: <key>: <reason>`` so the CLI can print it on one line.
    """

    def __init__(self, source: str | Path | None, key: str | None, reason: str):
        self.source = None if source is None else str(source)
        self.key = key
        self.reason = reason
        parts = [p for p in (self.source, key) if p]
        super().__init__(": ".join([*parts, reason]))
