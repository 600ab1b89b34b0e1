"""Reproductions of the papers' experiments, one module per experiment.

``robotsim reproduce NAME`` finds them here: the module ``foo_bar`` is the experiment
``foo-bar``. Each module defines

- ``HELP: str``: one line for ``robotsim reproduce --help``;
- ``add_arguments(parser: argparse.ArgumentParser) -> None``: its options (``--runs``,
  ``--out``, ``--seed``...);
- ``main(args: argparse.Namespace) -> int``: runs the experiment, writes its outputs
  atomically (``scenarios.outputs.atomic_directory``) and returns the exit status.

Modules keep heavy imports (matplotlib) inside ``main`` so that listing them is cheap.
"""

from __future__ import annotations

import importlib
import pkgutil
from types import ModuleType


def experiments() -> dict[str, ModuleType]:
    """The reproduction modules found in this package, by command name."""
    found = {}
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda i: i.name):
        if info.name.startswith("_") or info.ispkg:
            continue
        module = importlib.import_module(f"{__name__}.{info.name}")
        if all(hasattr(module, attr) for attr in ("HELP", "add_arguments", "main")):
            found[info.name.replace("_", "-")] = module
    return found
