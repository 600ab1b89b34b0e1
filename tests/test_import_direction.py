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
        elif isinstance(node, ast.ImportFrom) and (node.module or not node.level):
            found.append((node.lineno, from_module(node, module, is_package)))
        elif isinstance(node, ast.ImportFrom):  # from . import a, b: modules of the package
            base = from_module(node, module, is_package)
            found += [(node.lineno, f"{base}.{alias.name}") for alias in node.names]
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


def from_module(node: ast.ImportFrom, module: str, is_package: bool) -> str:
    """The absolute name of the module ``X`` of ``from X import ...`` in ``module`` (an
    ``__init__.py`` when ``is_package``): a relative ``X`` resolved against ``module``'s
    package, ``from . import a`` giving that package itself."""
    if not node.level:
        return node.module or ""
    parts = module.split(".")
    base = parts if is_package else parts[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join([*base, *([node.module] if node.module else [])])


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


def imported_test_modules(source: str, module: str, root: Path) -> list[tuple[int, str]]:
    """``(line, name)`` of the test modules (``tests/…/test_*.py`` under ``root``) that
    ``source`` (the text of test module ``module``) imports, each once a line: every module
    :func:`imported_modules` finds, and for ``from X import a`` (absolute or relative) also
    ``X.a``, as ``a`` may be a module of package ``X``. A name is a test module's when, cut
    after its first part starting with ``test_`` (``tests.a.test_b.f``: ``tests.a.test_b``),
    it names such a file (``from tests.helpers import test_data`` imports no test module)."""
    found = imported_modules(source, module, False)
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.ImportFrom) and node.module:
            base = from_module(node, module, False)
            found += [(node.lineno, f"{base}.{alias.name}") for alias in node.names]
    test_modules = set()
    for line, name in found:
        parts = name.split(".")
        first = next((i for i, part in enumerate(parts) if part.startswith("test_")), None)
        if parts[0] == "tests" and first is not None:
            path = root.joinpath(*parts[: first + 1]).with_suffix(".py")
            if path.is_file():
                test_modules.add((line, ".".join(parts[: first + 1])))
    return sorted(test_modules)


def imports_of_test_modules(root: Path) -> list[str]:
    """``"file:line imports name"`` for each import of a test module by a test module
    (``root / "tests"``, every ``test_*.py`` below it)."""
    bad = []
    for path in sorted((root / "tests").rglob("test_*.py")):
        name = ".".join(path.relative_to(root).with_suffix("").parts)
        for line, imported in imported_test_modules(path.read_text(), name, root):
            bad.append(f"{path.relative_to(root)}:{line} imports {imported}")
    return bad


def test_a_test_module_importing_another_in_any_form_is_reported(tmp_path):
    """The checker itself, on a made-up tree: one test module per form of importing test module
    ``tests/a/test_b.py``, each reported at its line; a module importing only helpers is not."""
    forms = {
        "test_import": "import tests.a.test_b\n",
        "test_import_as": "import tests.a.test_b as b\n",
        "test_from_package": "from tests.a import helpers, test_b\n",
        "test_from_module": "from tests.a.test_b import f\n",
        "test_from_dot": "from . import test_b\n",
        "test_from_dot_module": "from .test_b import f\n",
        "test_from_parent_package": "from ..a import test_b\n",
        "test_from_parent_module": "from ..a.test_b import f\n",
        "test_dynamic": "import importlib\nb = importlib.import_module('tests.a.test_b')\n",
        "test_lazy": "def later():\n    from tests.a.test_b import f as g\n    return g\n",
    }
    package = tmp_path / "tests" / "a"
    package.mkdir(parents=True)
    for init in (tmp_path / "tests", package):
        (init / "__init__.py").write_text("")
    (package / "helpers.py").write_text("test_data = 1\n")
    (package / "test_b.py").write_text("def f():\n    return 1\n")
    (package / "test_fine.py").write_text(
        "import tests.a.helpers\nfrom tests.a.helpers import test_data\nfrom . import helpers\n"
    )
    for name, source in forms.items():
        (package / f"{name}.py").write_text(source)
    lines = {"test_dynamic": 2, "test_lazy": 2}
    assert imports_of_test_modules(tmp_path) == sorted(
        f"tests/a/{name}.py:{lines.get(name, 1)} imports tests.a.test_b" for name in forms
    )


def test_no_test_module_imports_another_test_module():
    """What test modules share (cases, brute-force counts) lives in ``tests/helpers.py`` or
    ``tests/conftest.py``: a test module imported by another runs its module code there and
    ties the two modules' private names together."""
    root = Path(__file__).resolve().parent.parent
    assert len(list((root / "tests").rglob("test_*.py"))) > 20  # found, not an empty check
    assert imports_of_test_modules(root) == []
