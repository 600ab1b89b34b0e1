"""What each command imports: the CLI starts without the heavy libraries and takes each only
on the path that needs it (issue 17: ``import scenarios.cli`` and ``robotsim --help`` in
under 0.3 s; the figures are in BENCHMARKS.md, "First run").

Every command's ``--help`` starts without them too: the command modules import the scenarios
and the estimators (and with them numba) where a run reads them, and ``robotsim reproduce``
reads each experiment's one-line help from its source, importing only the chosen
experiment. A run imports what it runs.
Each case runs in a fresh interpreter and reads its ``sys.modules`` at the end: a module an
earlier test imported cannot hide an import here.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from scenarios.catalog import builtin_description, builtin_names
from scenarios.cli import COMMANDS
from scenarios.spec import load_scenario

ROOT = Path(__file__).resolve().parents[2]

#: The libraries that take a noticeable time to import, and what may bring each in.
HEAVY = ("numba", "rerun", "matplotlib", "pyarrow", "dask", "distributed", "scipy.stats")


def imported_after(code: str, cwd: Path) -> set[str]:
    """The modules of :data:`HEAVY` (or their sub-modules) imported by ``code`` in a new
    Python, whatever it printed."""
    probe = (
        f"{code}\nimport json, sys\n"
        f"heavy = {HEAVY!r}\n"
        "found = sorted(h for h in heavy if any(m == h or m.startswith(h + '.') for m in sys.modules))\n"
        "print('\\nIMPORTED ' + json.dumps(found))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", probe],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=120,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    assert done.returncode == 0, done.stderr
    line = done.stdout.rsplit("IMPORTED ", 1)[1]
    return set(json.loads(line))


def cli_code(*args: str) -> str:
    """Python that runs ``robotsim ARGS`` in-process and carries on after its exit."""
    return (
        "from scenarios.cli import main\n"
        f"try:\n    main({list(args)!r})\nexcept SystemExit:\n    pass\n"
    )


@pytest.mark.parametrize(
    "args",
    [
        (),  # the import alone
        ("--help",),
        ("scenarios",),
        ("run", "--help"),
        ("warmup", "--help"),
        ("campaign", "--help"),
        ("replay", "--help"),
        ("report", "--help"),
        ("reproduce", "--help"),
        ("campaign", "no-such-campaign.toml"),  # refused (exit 2) before any scenario is read
        ("run", "--seed", "not-a-number"),  # refused while parsing: nothing imported
    ],
    ids=lambda a: " ".join(a) or "import",
)
def test_the_cli_starts_without_the_heavy_libraries(args, tmp_path):
    code = cli_code(*args) if args else "import scenarios.cli"
    assert imported_after(code, tmp_path) == set()


@pytest.mark.slow  # a second of simulation and its estimation in a new interpreter
def test_a_run_without_recording_pulls_no_recording_reproduction_or_cluster_libraries(tmp_path):
    """A scenario simulated and localised through the library (as a campaign's worker does):
    numba for the kernels, but not rerun (and its pyarrow), matplotlib, dask or scipy.stats;
    and the ray kernels only with the ray test (off for the default belt)."""
    code = (
        "import sys\n"
        "from scenarios.runner import run_scenario\n"
        "from scenarios.spec import load_scenario\n"
        "run_scenario(load_scenario('hall').with_run(duration_s=1.0))\n"
        "assert 'intervals.sonar.rays' not in sys.modules, 'the ray kernels were imported'\n"
    )
    assert imported_after(code, tmp_path) == {"numba"}


def test_the_listing_reads_the_descriptions_the_validated_scenarios_have():
    """``robotsim scenarios`` reads each description from the file without validating it;
    it must be the one :func:`load_scenario` gives."""
    assert builtin_names()
    for name in builtin_names():
        assert builtin_description(name) == load_scenario(name).description, name


def test_every_command_names_a_module_and_functions_that_exist():
    """The table of sub-commands is only read when a command is chosen: check every entry."""
    import importlib

    for name, command in COMMANDS.items():
        module = importlib.import_module(command.module)
        for function in (command.add_arguments, command.handler):
            assert function is None or callable(getattr(module, function)), (name, function)


def test_the_experiments_are_listed_with_their_help_without_importing_them():
    """``robotsim reproduce --help`` reads ``HELP`` from each module's source: the same text
    the imported module holds, for every module of the package that is an experiment."""
    import importlib
    import pkgutil

    import scenarios.reproduce as package
    from scenarios.reproduce import experiment_helps

    listed = experiment_helps()
    found = {}
    for info in pkgutil.iter_modules(package.__path__):
        module = importlib.import_module(f"scenarios.reproduce.{info.name}")
        if all(hasattr(module, name) for name in ("HELP", "add_arguments", "main")):
            found[info.name.replace("_", "-")] = module
    assert set(listed) == set(found) and len(found) >= 5
    for name, module in found.items():
        assert listed[name] == (module.__name__, module.HELP), name
