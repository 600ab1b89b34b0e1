"""Helpers shared by the benchmark scripts: timing, the machine line, and ``BENCHMARKS.md`` sections.

Benchmarks are run as scripts (``python benchmarks/NAME.py``), so this module is imported as
``_common`` from the script's own folder (Python puts it first on ``sys.path``).
"""

from __future__ import annotations

import os
import platform
import subprocess
import sys
import time
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from scenarios.outputs import write_text

BENCHMARKS_MD = Path(__file__).resolve().parent.parent / "BENCHMARKS.md"
"""The results file at the repository root."""


def best_seconds(fn: Callable[[], object], repeats: int, number: int = 1) -> float:
    """Best wall time of one call of ``fn`` over ``repeats`` rounds of ``number`` calls, in s.

    The minimum (as ``timeit`` reports) discards the rounds slowed by other processes on a
    shared machine.
    """
    best = np.inf
    for _ in range(max(1, repeats)):
        start = time.perf_counter()
        for _ in range(number):
            fn()
        best = min(best, (time.perf_counter() - start) / number)
    return float(best)


def timed(fn: Callable[[], object]) -> tuple[object, float]:
    """``(fn(), seconds)`` of one call."""
    start = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - start


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def machine_line(*packages: str) -> str:
    """One line naming the CPU, the cores, the load, Python and the given packages' versions."""
    from importlib.metadata import PackageNotFoundError, version

    versions = []
    for name in ("numpy", *packages):
        try:
            versions.append(f"{name} {version(name)}")
        except PackageNotFoundError:
            versions.append(f"{name} (not installed)")
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    day = datetime.now(UTC).strftime("%Y-%m-%d")
    return (
        f"{_cpu_model()}, {os.cpu_count()} cores, load {load:.1f}, Python "
        f"{sys.version.split()[0]}, {', '.join(versions)}; measured {day}"
    )


def markdown_table(header: list[str], rows: list[list[str]]) -> str:
    """A GitHub markdown table."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)


def write_section(title: str, body: str, path: Path = BENCHMARKS_MD) -> None:
    """Put ``## title`` + ``body`` into ``path``: replace that section if present, else append.

    The section runs to the next ``## `` heading or the end of the file; the rest of the file
    (other people's sections) is kept byte for byte. The file is re-read right before the
    write and replaced atomically.
    """
    heading = f"## {title}"
    text = path.read_text(encoding="utf-8") if path.exists() else "# Benchmarks\n"
    lines = text.splitlines(keepends=True)
    start = next((i for i, line in enumerate(lines) if line.rstrip("\n") == heading), None)
    section = f"{heading}\n\n{body.strip()}\n"
    if start is None:
        new = text.rstrip("\n") + "\n\n" + section
    else:
        end = next(
            (i for i in range(start + 1, len(lines)) if lines[i].startswith("## ")), len(lines)
        )
        tail = "".join(lines[end:])
        new = "".join(lines[:start]) + section + ("\n" + tail if tail else "")
    write_text(path, new)


def code_label(tree: Path) -> str:
    """The tree's commit (``git describe --always --dirty``), or its folder name."""
    try:
        done = subprocess.run(
            ["git", "-C", str(tree), "describe", "--always", "--dirty"],
            capture_output=True,
            text=True,
            check=True,
        )
        return done.stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return tree.name
