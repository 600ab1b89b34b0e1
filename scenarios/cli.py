"""The ``robotsim`` command: run scenarios headless, list them, reproduce the papers.

    robotsim run [SCENARIO] [--rrd PATH] [--summary PATH] [--seed N] [--duration S]
                 [--sensor-log PATH]
    robotsim replay LOG [--estimation FILE] [--summary PATH]
    robotsim scenarios
    robotsim reproduce NAME [options]

A user's mistake (bad scenario file, impossible setting, NaN reading) prints one line
``robotsim: error: <file>: <key>: <reason>`` on stderr and exits with status 2; no
traceback and no half-written output.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from intervals.errors import IntervalError
from localization.errors import EstimationError
from robotsim.errors import RobotsimError
from scenarios.errors import ScenarioError

#: The errors that are a user's to fix: printed on one line, exit status 2.
USER_ERRORS = (ScenarioError, RobotsimError, EstimationError, IntervalError)
EXIT_USER_ERROR = 2


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``robotsim`` with its sub-commands."""
    from scenarios import commands, sensor_log
    from scenarios.reproduce import experiments

    parser = argparse.ArgumentParser(
        prog="robotsim",
        description="Mobile-robot simulation and guaranteed-localisation testbed.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    run = sub.add_parser("run", help="run a scenario headless; write its recording and summary")
    commands.add_run_arguments(run)
    run.set_defaults(handler=commands.run)

    replay = sub.add_parser("replay", help="run the localiser on a sensor log (no simulator)")
    sensor_log.add_replay_arguments(replay)
    replay.set_defaults(handler=sensor_log.replay_command)

    listing = sub.add_parser("scenarios", help="list the built-in scenarios")
    listing.set_defaults(handler=commands.list_scenarios)

    reproduce = sub.add_parser("reproduce", help="reproduce a paper's experiment")
    rsub = reproduce.add_subparsers(dest="experiment", required=True, metavar="NAME")
    for name, module in experiments().items():
        p = rsub.add_parser(name, help=module.HELP, description=module.HELP)
        module.add_arguments(p)
        p.set_defaults(handler=module.main)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the console script; returns the process exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.handler(args) or 0)
    except USER_ERRORS as exc:
        print(f"robotsim: error: {exc}", file=sys.stderr)
        return EXIT_USER_ERROR
    except OSError as exc:
        # A file system failure (unwritable folder, disk full) while reading or writing
        # outputs: one line, and the atomic writers have already removed their partial files.
        target = f" {exc.filename}" if exc.filename else ""
        print(f"robotsim: error:{target}: {exc.strerror or exc}", file=sys.stderr)
        return EXIT_USER_ERROR
    except KeyboardInterrupt:
        print("robotsim: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
