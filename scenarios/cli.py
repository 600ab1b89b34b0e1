"""The ``robotsim`` command: run scenarios headless, list them, reproduce the papers.

    robotsim [--debug] [--version] COMMAND ...
    robotsim run [SCENARIO] [--rrd PATH] [--summary PATH] [--seed N] [--duration S]
                 [--sensor-log PATH]
    robotsim replay LOG [--estimation FILE] [--summary PATH]
    robotsim scenarios
    robotsim campaign FILE [--out DIR] [--resume] [--workers N] [--cluster local | --scheduler ADDRESS]
    robotsim report RESULTS [--out DIR]
    robotsim reproduce NAME [options]
    robotsim warmup [--only run | --only filters]

Exit statuses and what stderr holds (always at most one line, without ``--debug``):

- 0: done; 1: the run broke its own guarantee (the line says how);
- 2: a user's mistake (a bad scenario file, option or output path, a full disk):
  ``robotsim: error: <file>: <key>: <reason>``; nothing written;
- 3: a defect of robotsim (a numerical or internal failure on input that passed
  validation): one line saying so, the traceback in a crash file whose path the line gives
  (``--debug`` prints the traceback instead);
- 128 + n: stopped by signal n (SIGINT, SIGTERM, SIGHUP); temporary files removed; 141
  (128 + SIGPIPE), silently, when the reader of stdout left (``robotsim scenarios | head -1``).
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import os
import platform
import signal
import sys
import tempfile
import threading
import traceback
import warnings
from collections.abc import Callable, Iterator, Sequence
from typing import Any, NamedTuple, NoReturn

from robotsim.errors import RobotsimError
from scenarios.errors import ScenarioError
from scenarios.outputs import STOP_SIGNALS

#: The errors that are a user's to fix: printed on one line, exit status 2.
USER_ERRORS = (ScenarioError, RobotsimError)
EXIT_USER_ERROR = 2
#: A defect of the tool (anything else that escapes a command).
EXIT_INTERNAL_ERROR = 3


#: The environment variable of rerun's native logger (set to "off" unless the user set it).
RERUN_LOG_VARIABLE = "RUST_LOG"

#: The distribution whose version ``robotsim --version`` prints.
DISTRIBUTION = "robotsim-testbed"


class Stopped(BaseException):
    """A stop signal arrived; unwinds like KeyboardInterrupt (cleanup runs, nothing moves)."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


class OneLineParser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line (exit status 2), as every error."""

    def error(self, message: str) -> NoReturn:
        _say(f"{self.prog}: error: {message} (see {self.prog} --help)")
        raise SystemExit(EXIT_USER_ERROR)


def version() -> str:
    """The installed version of the testbed (``unknown`` when run from a bare source tree)."""
    from importlib import metadata  # read only when asked for: it takes a tenth of the start-up

    try:
        return metadata.version(DISTRIBUTION)
    except metadata.PackageNotFoundError:
        return "unknown"


class Command(NamedTuple):
    """A sub-command of ``robotsim``: its line in ``robotsim --help`` and the module that
    holds its options and its handler. The module is imported only when the command is
    chosen, so that ``robotsim --help`` and ``robotsim scenarios`` start in a fraction of a
    second (none of numba, rerun, matplotlib, pyarrow or dask: ``tests/scenarios/test_cli_imports.py``)."""

    help: str
    module: str
    #: The module's function that adds the command's options (None: it takes none).
    add_arguments: str | None
    #: The module's function that runs the command (None: its own sub-commands set one).
    handler: str | None

    def configure(self, parser: argparse.ArgumentParser) -> None:
        """Import the command's module; give ``parser`` its options and its handler."""
        module = importlib.import_module(self.module)
        if self.add_arguments is not None:
            getattr(module, self.add_arguments)(parser)
        if self.handler is not None:
            parser.set_defaults(handler=getattr(module, self.handler))


#: The sub-commands, in the order ``robotsim --help`` lists them.
COMMANDS = {
    "run": Command(
        "run a scenario headless; write its recording and summary",
        "scenarios.commands",
        "add_run_arguments",
        "run",
    ),
    "replay": Command(
        "run the localiser on a sensor log (no simulator)",
        "scenarios.sensor_log",
        "add_replay_arguments",
        "replay_command",
    ),
    "scenarios": Command(
        "list the built-in scenarios", "scenarios.commands", None, "list_scenarios"
    ),
    "campaign": Command(
        "run every scenario x seed x setting of a campaign file; one results table",
        "scenarios.campaign",
        "add_arguments",
        "main",
    ),
    "report": Command(
        "aggregate a campaign's results per setting (confidence intervals, figures)",
        "scenarios.report",
        "add_arguments",
        "main",
    ),
    "reproduce": Command(
        "reproduce a paper's experiment", "scenarios.reproduce", "add_arguments", None
    ),
    "warmup": Command(
        "compile the numba kernels of the built-in paths into the disk cache (once, after install)",
        "scenarios.warmup",
        "add_arguments",
        "main",
    ),
}


class LazySubcommands(argparse._SubParsersAction):
    """Sub-parsers each given its options only when its command is the one chosen (argparse
    reaches a sub-parser only through this action's call): ``configure(name, sub_parser)``
    is called then. ``robotsim`` configures its commands from :data:`COMMANDS`; ``robotsim
    reproduce`` its experiments the same way (``scenarios.reproduce``). Made by
    :func:`add_lazy_subcommands`."""

    configure: Callable[[str, argparse.ArgumentParser], None]

    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: argparse.Namespace,
        values: str | Sequence[Any] | None,
        option_string: str | None = None,
    ) -> None:
        assert isinstance(values, list)  # nargs=PARSER: the command and its arguments
        name = values[0]
        if name in self._name_parser_map:  # else argparse reports the invalid choice
            self.configure(name, self._name_parser_map[name])
        super().__call__(parser, namespace, values, option_string)


def add_lazy_subcommands(
    parser: argparse.ArgumentParser,
    configure: Callable[[str, argparse.ArgumentParser], None],
    **options: Any,
) -> LazySubcommands:
    """``parser.add_subparsers(**options)`` as :class:`LazySubcommands` calling ``configure``."""
    sub = parser.add_subparsers(action=LazySubcommands, **options)
    assert isinstance(sub, LazySubcommands)
    sub.configure = configure
    return sub


class VersionAction(argparse.Action):
    """``--version``: print ``robotsim <version>`` and exit (the version looked up only then)."""

    def __init__(self, option_strings: Sequence[str], dest: str, **kwargs: Any):
        kwargs.setdefault("help", "show program's version number and exit")
        super().__init__(
            option_strings, argparse.SUPPRESS, nargs=0, default=argparse.SUPPRESS, **kwargs
        )

    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: argparse.Namespace,
        values: str | Sequence[Any] | None,
        option_string: str | None = None,
    ) -> None:
        print(f"robotsim {version()}")
        parser.exit()


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``robotsim`` with its sub-commands (each configured only once
    chosen: :class:`LazySubcommands`)."""
    parser = OneLineParser(
        prog="robotsim",
        description="Mobile-robot simulation and guaranteed-localisation testbed.",
    )
    parser.add_argument("--version", action=VersionAction)
    parser.add_argument(
        "--debug",
        action="store_true",
        help="on an internal failure print the full traceback (and any warnings) to stderr",
    )
    sub = add_lazy_subcommands(
        parser,
        lambda name, chosen: COMMANDS[name].configure(chosen),
        dest="command",
        required=True,
        metavar="COMMAND",
    )
    for name, command in COMMANDS.items():
        sub.add_parser(name, help=command.help)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the console script; returns the process exit status."""
    # rerun's native logger writes to stderr on its own (a dropped stream on a stop, a
    # failed write); its failures reach us as exceptions, so keep stderr to our one line.
    os.environ.setdefault(RERUN_LOG_VARIABLE, "off")
    parser = build_parser()
    args = parser.parse_args(argv)
    with warnings.catch_warnings(record=True) as caught, _stop_signals_raise():
        warnings.simplefilter("default")
        try:
            if getattr(args, "check", None):
                args.check(args)
            status = int(args.handler(args) or 0)
            sys.stdout.flush()  # a closed pipe shows here, not at the interpreter's exit
        except BrokenPipeError:
            # the reader of stdout left (``robotsim scenarios | head -1``): stop quietly, as a
            # command killed by SIGPIPE does
            _drop_stdout()
            return 128 + signal.SIGPIPE
        except USER_ERRORS as exc:
            _say(f"robotsim: error: {exc}")
            return EXIT_USER_ERROR
        except OSError as exc:
            # A file system failure (unwritable folder, full disk) while reading or writing:
            # the atomic writers have removed their temporaries and name the user's path.
            target = f"{exc.filename}: " if exc.filename else ""
            _say(f"robotsim: error: {target}{exc.strerror or exc}")
            return EXIT_USER_ERROR
        except MemoryError:
            _say(
                "robotsim: error: out of memory: the run needs more memory than this machine "
                "has (ask for fewer runs, steps or seconds)"
            )
            return EXIT_USER_ERROR
        except KeyboardInterrupt:
            _quiet_finalisers()
            _say("robotsim: interrupted")
            return 128 + signal.SIGINT
        except Stopped as stop:
            _quiet_finalisers()
            _say(f"robotsim: stopped by {stop}")
            return 128 + stop.signum
        except Exception as exc:  # every other failure is ours: say so, keep the traceback
            return _internal_failure(exc, argv, caught, debug=args.debug)
    if args.debug:
        for warning in caught:
            _say(f"robotsim: warning: {warning.category.__name__}: {warning.message}")
    return status


def _internal_failure(
    exc: BaseException,
    argv: Sequence[str] | None,
    caught: list[warnings.WarningMessage],
    *,
    debug: bool,
) -> int:
    """Report a failure of the tool: one line; the traceback to stderr or a crash file."""
    report = _crash_report(exc, argv, caught)
    summary = f"{type(exc).__name__}: {exc}"
    if debug:
        sys.stderr.write(report)
        _say(f"robotsim: internal error (a defect of robotsim, not of your input): {summary}")
        return EXIT_INTERNAL_ERROR
    try:
        with tempfile.NamedTemporaryFile(
            "w", prefix="robotsim-crash-", suffix=".txt", delete=False, encoding="utf-8"
        ) as crash:
            crash.write(report)
        where = f"traceback in {crash.name}"
    except OSError as write_error:
        where = f"no crash file ({write_error.strerror or write_error}); rerun with --debug"
    _say(
        f"robotsim: internal error (a defect of robotsim, not of your input; please report it): "
        f"{summary}; {where}"
    )
    return EXIT_INTERNAL_ERROR


def _crash_report(
    exc: BaseException, argv: Sequence[str] | None, caught: list[warnings.WarningMessage]
) -> str:
    """What a defect report needs: versions, the command line, the traceback, the warnings."""
    lines = [
        f"robotsim {version()} on Python {platform.python_version()} ({platform.platform()})",
        f"arguments: {list(sys.argv[1:] if argv is None else argv)!r}",
        "",
        *traceback.format_exception(exc),
    ]
    lines += [
        f"warning: {w.category.__name__}: {w.message} ({w.filename}:{w.lineno})" for w in caught
    ]
    return "\n".join(line.rstrip("\n") for line in lines) + "\n"


@contextlib.contextmanager
def _stop_signals_raise() -> Iterator[None]:
    """While the block runs, SIGTERM and SIGHUP raise :class:`Stopped` (once; a repeat
    during the cleanup is ignored). Only the main thread may set handlers: elsewhere a no-op."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def stop(signum: int, frame: object) -> None:
        for other in STOP_SIGNALS:
            signal.signal(other, signal.SIG_IGN)
        raise Stopped(signum)

    previous = {signum: signal.signal(signum, stop) for signum in STOP_SIGNALS}
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


def _quiet_finalisers() -> None:
    """After a stop, let objects whose construction the signal cut short (a rerun stream
    without its native half) fail to finalise silently: the process is exiting, and their
    "Exception ignored in __del__" would break the one line on stderr."""
    sys.unraisablehook = lambda unraisable: None


def _drop_stdout() -> None:
    """Point stdout at the null device, so that the interpreter's final flush of what is
    still buffered for a reader that left raises nothing."""
    null = os.open(os.devnull, os.O_WRONLY)
    os.dup2(null, sys.stdout.fileno())
    os.close(null)


def _say(text: str) -> None:
    """Print ``text`` on stderr as exactly one line, whatever it holds (line breaks in a
    file name or a message become spaces; characters the stream cannot encode are escaped)."""
    line = " ".join(text.splitlines())
    encoding = getattr(sys.stderr, "encoding", None) or "utf-8"
    sys.stderr.write(line.encode(encoding, "backslashreplace").decode(encoding) + "\n")
    sys.stderr.flush()


if __name__ == "__main__":
    sys.exit(main())
