"""The four packages keep their import direction (ARCHITECTURE.md, package layout):

    scenarios -> localization -> intervals,    scenarios -> robotsim

``intervals`` and ``robotsim`` import none of the others and ``localization`` never imports
``robotsim`` (nor ``scenarios``). Every module's source is parsed with :mod:`ast` and every
import statement in it is read, wherever it sits (inside functions, branches, ``try``), as
are ``importlib.import_module("...")`` and ``__import__("...")`` calls with a literal name:
a lazy import cannot hide an edge. ``validated_records`` (the declared bounds of settings
fields) sits below all four and imports none of them.
"""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

#: The first-party packages each package may import (besides itself).
ALLOWED = {
    "validated_records": frozenset(),
    "robotsim": frozenset({"validated_records"}),
    "intervals": frozenset({"validated_records"}),
    "localization": frozenset({"intervals", "validated_records"}),
    "scenarios": frozenset({"localization", "intervals", "robotsim", "validated_records"}),
}
DYNAMIC_IMPORTERS = {"import_module", "__import__"}


def imported_modules(source: str, module: str, is_package: bool) -> list[tuple[int, str]]:
    """``(line, absolute module name)`` of every import in ``source`` in line order (the text of ``module``;
    ``is_package`` for an ``__init__.py``), relative imports resolved."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and not node.level:
            found.append((node.lineno, node.module or ""))
        elif isinstance(node, ast.ImportFrom):  # relative: resolved against ``module``
            parts = module.split(".")
            base = parts if is_package else parts[:-1]
            base = base[: len(base) - (node.level - 1)]
            if node.module:
                found.append((node.lineno, ".".join([*base, node.module])))
            else:  # from . import a, b: the names are modules of the base package
                found += [(node.lineno, ".".join([*base, alias.name])) for alias in node.names]
        elif isinstance(node, ast.Call):
            func = node.func
            called = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", None)
            if (
                called in DYNAMIC_IMPORTERS
                and node.args
                and isinstance(node.args[0], ast.Constant)
                and isinstance(node.args[0].value, str)
            ):
                found.append((node.lineno, node.args[0].value))
    return sorted(found)


def violations(root: Path, package: str) -> list[str]:
    """``"file:line imports name"`` for each import of a first-party package that
    :data:`ALLOWED` forbids to ``package`` (its sources under ``root / package``)."""
    bad = []
    for path in sorted((root / package).rglob("*.py")):
        relative = path.relative_to(root).with_suffix("")
        is_package = relative.name == "__init__"
        parts = relative.parts[:-1] if is_package else relative.parts
        for line, name in imported_modules(path.read_text(), ".".join(parts), is_package):
            top = name.split(".")[0]
            if top in ALLOWED and top != package and top not in ALLOWED[package]:
                bad.append(f"{path.relative_to(root)}:{line} imports {name}")
    return bad


@pytest.mark.parametrize("package", sorted(ALLOWED))
def test_package_imports_only_the_packages_below_it(package):
    root = Path(importlib.import_module(package).__path__[0]).parent  # the imported copy
    sources = list((root / package).rglob("*.py"))
    assert sources and all(p.stat().st_size > 0 for p in sources)  # found, not an empty check
    assert violations(root, package) == []


def test_lazy_relative_and_dynamic_imports_are_caught(tmp_path):
    """The checker itself: forbidden edges hidden in a function and a branch, and behind an
    ``import_module`` call, are reported; relative imports resolve inside the package."""
    (tmp_path / "intervals" / "inner").mkdir(parents=True)
    (tmp_path / "intervals" / "__init__.py").write_text("from intervals import boxes\n")
    (tmp_path / "intervals" / "inner" / "__init__.py").write_text("from .. import sivia\n")
    (tmp_path / "intervals" / "inner" / "lazy.py").write_text(
        "import numpy\n"
        "from ..boxes import volume\n"
        "def later():\n"
        "    if volume:\n"
        "        from robotsim.maps import builtin_map\n"
        "    import localization.gaussian as g\n"
        "    return importlib.import_module('scenarios.spec'), g\n"
    )
    (tmp_path / "localization").mkdir()
    (tmp_path / "localization" / "fine.py").write_text(
        "from intervals.boxes import volume\nfrom . import gaussian\n"
    )
    assert violations(tmp_path, "intervals") == [
        "intervals/inner/lazy.py:5 imports robotsim.maps",
        "intervals/inner/lazy.py:6 imports localization.gaussian",
        "intervals/inner/lazy.py:7 imports scenarios.spec",
    ]
    assert violations(tmp_path, "localization") == []
    lazy = (tmp_path / "intervals" / "inner" / "lazy.py").read_text()
    assert imported_modules(lazy, "intervals.inner.lazy", False)[:2] == [
        (1, "numpy"),
        (2, "intervals.boxes"),
    ]
    assert imported_modules("from .. import sivia\n", "intervals.inner", True) == [
        (1, "intervals.sivia")
    ]


def imported_test_modules(source: str, module: str) -> list[tuple[int, str]]:
    """``(line, name)`` of the test modules (``tests.….test_*``) that ``source`` (the text of
    test module ``module``) imports: by :func:`imported_modules`, and the names of an absolute
    ``from tests.… import test_x``, which name modules too."""
    found = imported_modules(source, module, False)
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.ImportFrom) and node.module and not node.level:
            found += [(node.lineno, f"{node.module}.{alias.name}") for alias in node.names]
    return sorted(
        (line, name)
        for line, name in found
        if name.startswith("tests.") and name.split(".")[-1].startswith("test_")
    )


def test_imports_of_test_modules_are_found_in_every_form():
    source = (
        "import tests.helpers\n"
        "from tests.helpers import DEFAULT_BELT\n"
        "from tests.intervals import test_x\n"
        "from tests.intervals.test_y import case\n"
        "import tests.intervals.test_z\n"
        "from . import test_w\n"
    )
    assert imported_test_modules(source, "tests.intervals.test_v") == [
        (3, "tests.intervals.test_x"),
        (4, "tests.intervals.test_y"),
        (5, "tests.intervals.test_z"),
        (6, "tests.intervals.test_w"),
    ]


def test_no_test_module_imports_another_test_module():
    """What test modules share (cases, brute-force counts) lives in ``tests/helpers.py`` or
    ``tests/conftest.py``: a test module imported by another runs its module code there and
    ties the two modules' private names together."""
    root = Path(__file__).resolve().parent.parent
    modules = sorted((root / "tests").rglob("test_*.py"))
    assert len(modules) > 20  # found, not an empty check
    bad = []
    for path in modules:
        name = ".".join(path.relative_to(root).with_suffix("").parts)
        for line, imported in imported_test_modules(path.read_text(), name):
            bad.append(f"{path.relative_to(root)}:{line} imports {imported}")
    assert bad == []
