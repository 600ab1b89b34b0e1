"""Reproductions of the papers' experiments, one module per experiment.

``robotsim reproduce NAME`` finds them here: the module ``foo_bar`` is the experiment
``foo-bar``. Each module defines

- ``HELP: str``: one line for ``robotsim reproduce --help``, a string literal (it is read
  from the source, :func:`declared_help`, without importing the module);
- ``add_arguments(parser: argparse.ArgumentParser) -> None``: its options (``--runs``,
  ``--out``, ``--seed``...);
- ``main(args: argparse.Namespace) -> int``: runs the experiment, writes its outputs
  atomically (``scenarios.outputs.atomic_directory``) and returns the exit status.

An experiment's module is imported only when it is the one chosen, so that ``robotsim
reproduce --help`` starts without numba (every experiment imports the estimators); heavy
imports that only the run needs (matplotlib) stay inside ``main`` all the same. ``robotsim``
imports this package only when the command is ``reproduce`` (:data:`scenarios.cli.COMMANDS`).
"""

from __future__ import annotations

import argparse
import ast
import importlib
import pkgutil
from pathlib import Path
from types import ModuleType


def declared_help(path: Path) -> str | None:
    """The string literal a module's source assigns to ``HELP`` at its top level (None
    without one: the module is not an experiment)."""
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(
            isinstance(target, ast.Name) and target.id == "HELP" for target in node.targets
        ):
            return str(ast.literal_eval(node.value))
    return None


def experiment_helps() -> dict[str, tuple[str, str]]:
    """The experiments of this package without importing them: command name -> (module
    name, ``HELP``)."""
    found = {}
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda i: i.name):
        if info.name.startswith("_") or info.ispkg:
            continue
        line = declared_help(Path(__path__[0]) / f"{info.name}.py")
        if line is not None:
            found[info.name.replace("_", "-")] = (f"{__name__}.{info.name}", line)
    return found


def experiments() -> dict[str, ModuleType]:
    """The reproduction modules of this package, imported, by command name."""
    return {
        name: importlib.import_module(module) for name, (module, _) in experiment_helps().items()
    }


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The experiments of ``robotsim reproduce``, one sub-command each; an experiment's
    module is imported, and its options added, once it is chosen."""
    from scenarios.cli import add_lazy_subcommands
    from scenarios.commands import check_reproduce

    helps = experiment_helps()

    def configure(name: str, chosen: argparse.ArgumentParser) -> None:
        module = importlib.import_module(helps[name][0])
        module.add_arguments(chosen)
        chosen.set_defaults(handler=module.main, check=check_reproduce)

    sub = add_lazy_subcommands(parser, configure, dest="experiment", required=True, metavar="NAME")
    for name, (_, line) in helps.items():
        sub.add_parser(name, help=line, description=line)
