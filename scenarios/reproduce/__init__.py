"""Reproductions of the papers' experiments, one module per experiment.

``robotsim reproduce NAME`` finds them here: the module ``foo_bar`` is the experiment
``foo-bar``. Each module defines

- ``HELP: str``: one line for ``robotsim reproduce --help``;
- ``add_arguments(parser: argparse.ArgumentParser) -> None``: its options (``--runs``,
  ``--out``, ``--seed``...);
- ``main(args: argparse.Namespace) -> int``: runs the experiment, writes its outputs
  atomically (``scenarios.outputs.atomic_directory``) and returns the exit status.

Modules keep heavy imports (matplotlib) inside ``main`` so that listing them is cheap.
``robotsim`` imports this package (and so every experiment module) only when the command
is ``reproduce`` (:data:`scenarios.cli.COMMANDS`).
"""

from __future__ import annotations

import argparse
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


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The experiments of ``robotsim reproduce``, one sub-command each, with their options."""
    from scenarios.commands import check_reproduce

    sub = parser.add_subparsers(dest="experiment", required=True, metavar="NAME")
    for name, module in experiments().items():
        p = sub.add_parser(name, help=module.HELP, description=module.HELP)
        module.add_arguments(p)
        p.set_defaults(handler=module.main, check=check_reproduce)
