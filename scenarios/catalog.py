"""The built-in scenarios as a list: their names, files and one-line descriptions.

Read straight from the TOML files of ``scenarios/builtin/``, without validating them (that is
:func:`scenarios.spec.load_scenario`'s job, and every built-in passes it:
``tests/scenarios/test_catalog.py``), so that ``robotsim scenarios`` and the help of
``robotsim run`` import neither the simulator nor the estimators.
"""

from __future__ import annotations

import tomllib
from importlib import resources

#: The built-in scenarios: one TOML file per built-in map, in ``scenarios/builtin/``.
BUILTIN_FOLDER = resources.files("scenarios") / "builtin"

#: The scenario ``robotsim run`` runs when none is named, and the map a ``[map]`` table
#: without a ``file`` or ``builtin`` key means.
DEFAULT_MAP = "hall"


def builtin_names() -> tuple[str, ...]:
    """Names of the built-in scenarios (the TOML files of ``scenarios/builtin``)."""
    files = BUILTIN_FOLDER.iterdir()
    return tuple(sorted(f.name[: -len(".toml")] for f in files if f.name.endswith(".toml")))


def builtin_description(name: str) -> str:
    """The top-level ``description`` of the built-in scenario ``name`` ("" when it has none),
    as :func:`scenarios.spec.load_scenario` reads it."""
    text = (BUILTIN_FOLDER / f"{name}.toml").read_text(encoding="utf-8")
    description = tomllib.loads(text).get("description", "")
    return str(description)
