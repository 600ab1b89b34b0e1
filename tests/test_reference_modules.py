"""The numpy references (``intervals.sonar.reference``, ``localization.reference``) stay out
of the production path: no production module imports them, at import time or lazily.

Statically, every import statement of every production module is read (:mod:`ast`, wherever
it sits, ``from package import module`` included); dynamically, a fresh interpreter imports
every production module and must not have loaded a reference module.
"""

from __future__ import annotations

import ast
import importlib
import subprocess
import sys
from pathlib import Path

REFERENCES = ("intervals.sonar.reference", "localization.reference")
PRODUCTION = ("validated_records", "robotsim", "intervals", "localization", "scenarios")


def _is_reference(name: str) -> bool:
    return any(name == ref or name.startswith(ref + ".") for ref in REFERENCES)


def _module_name(root: Path, path: Path) -> str:
    parts = path.relative_to(root).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def production_sources() -> list[tuple[str, Path]]:
    """``(module name, source path)`` of every production module of the imported checkout."""
    found = []
    for package in PRODUCTION:
        root = Path(importlib.import_module(package).__path__[0]).parent
        for path in sorted((root / package).rglob("*.py")):
            name = _module_name(root, path)
            if not _is_reference(name):
                found.append((name, path))
    return found


def imported_names(source: str, module: str, is_package: bool) -> set[str]:
    """Every module an import in ``source`` may name: ``import a.b``, ``from a import b``
    (both ``a`` and ``a.b``), relative imports resolved against ``module``."""
    names = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = module.split(".") if is_package else module.split(".")[:-1]
                parts = parts[: len(parts) - (node.level - 1)]
                base = ".".join([*parts, *([node.module] if node.module else [])])
            names.add(base)
            names.update(f"{base}.{alias.name}" for alias in node.names)
    return names


def test_no_production_module_imports_a_reference():
    sources = production_sources()
    assert len(sources) > 50  # the walk found the packages
    bad = [
        f"{name} imports {imported}"
        for name, path in sources
        for imported in sorted(imported_names(path.read_text(), name, path.name == "__init__.py"))
        if _is_reference(imported)
    ]
    assert not bad, bad


def test_the_names_an_import_may_bring_are_all_seen():
    """The reader above catches each way of writing the import (it could not fail else)."""
    source = (
        "from intervals.sonar import reference\n"
        "import localization.reference.dead_reckoning\n"
        "def lazy():\n    from .reference import cone\n"
    )
    names = imported_names(source, "intervals.sonar.rays", False)
    assert {"intervals.sonar.reference", "localization.reference.dead_reckoning"} <= names
    assert "intervals.sonar.reference.cone" in names


def test_importing_every_production_module_loads_no_reference():
    """A fresh interpreter imports them all: no reference module is loaded; importing one
    afterwards shows up in the same check (so it can fail)."""
    modules = [name for name, path in production_sources() if path.name != "__main__.py"]
    check = f"print(sorted(m for m in sys.modules if m.startswith({REFERENCES!r})))\n"
    program = (
        "import importlib, sys\n"
        f"for name in {modules!r}:\n"
        "    importlib.import_module(name)\n"
        f"{check}"
        "import intervals.sonar.reference.cone\n"
        f"{check}"
    )
    done = subprocess.run(
        [sys.executable, "-c", program], capture_output=True, text=True, check=True, timeout=300
    )
    loaded, then = done.stdout.strip().splitlines()
    assert loaded == "[]", loaded
    assert "'intervals.sonar.reference.cone'" in then
