"""The ``run`` and ``scenarios`` sub-commands of ``robotsim`` (``scenarios.cli`` wires them).

``robotsim run [SCENARIO] [--rrd PATH] [--summary PATH] [--seed N] [--duration S]
[--spawn | --connect [ADDR]]`` runs one scenario headless and writes its rerun recording and
its JSON summary, both atomically: a user error or a crash leaves neither file behind (nor a
half of one); ``--spawn`` or ``--connect`` also streams the recording, with the same
blueprint, to a viewer it starts or to a running one. Both destinations are checked before
anything runs, and neither may be an input of the run (the scenario file, the map file it
names). The recording is read back before it is moved into place. The run checks its own
guarantee: exit status 1 when, although the sonar has no faults configured, the truth left an
interval set or an epoch found no set at all.

``robotsim reproduce NAME``'s options are checked here too (:func:`check_reproduce`) before
the experiment runs: ``--out`` replaces only a folder an earlier reproduction wrote.
"""

from __future__ import annotations

import argparse
import sys
import time
import tomllib
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

from scenarios import outputs
from scenarios.catalog import DEFAULT_MAP, builtin_description, builtin_names
from scenarios.errors import ScenarioError

if TYPE_CHECKING:  # the simulator and the estimators are imported when a run starts
    from scenarios.spec import ScenarioSpec

#: Where ``robotsim run`` writes when no path is given.
DEFAULT_RUNS_DIR = Path("runs")

#: The options of ``robotsim run`` that override a key of the scenario's ``[run]``.
RUN_OPTIONS = {"run.seed": "--seed", "run.duration_s": "--duration"}

#: Limits of the reproductions' Monte Carlo options: beyond them the arrays of estimates do
#: not fit in memory (``--runs`` times ``--steps`` states per filter).
MAX_RUNS = 100_000
MAX_RUN_STEPS = 20_000_000

#: The part of the progress bar the run (simulation and estimation) fills; the recording
#: fills the rest.
RUN_SHARE = 0.9


def add_run_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``robotsim run``."""
    parser.add_argument(
        "scenario",
        nargs="?",
        default=DEFAULT_MAP,
        metavar="SCENARIO",
        help=f"a built-in scenario ({', '.join(builtin_names())}) or a TOML file (default: %(default)s)",
    )
    parser.add_argument(
        "--rrd",
        type=Path,
        metavar="PATH",
        help="recording to write (default: runs/<scenario>-seed<N>.rrd)",
    )
    parser.add_argument(
        "--summary",
        type=Path,
        metavar="PATH",
        help="summary JSON to write (default: runs/<scenario>-seed<N>.json)",
    )
    parser.add_argument(
        "--sensor-log",
        type=Path,
        metavar="PATH",
        help="also write the run's sensor log (Parquet, scenarios.sensor_log; for robotsim replay)",
    )
    parser.add_argument("--seed", type=int, metavar="N", help="override the scenario's seed")
    parser.add_argument(
        "--duration", type=float, metavar="S", help="override the scenario's duration, seconds"
    )
    live = parser.add_mutually_exclusive_group()
    live.add_argument(
        "--spawn",
        action="store_true",
        help="also start rerun's viewer and stream the recording to it (same blueprint)",
    )
    live.add_argument(
        "--connect",
        nargs="?",
        const="",
        metavar="ADDR",
        help="also stream the recording to a running viewer at ADDR (host:port or a "
        "rerun+http:// URL; default 127.0.0.1:9876)",
    )


def run(args: argparse.Namespace) -> int:
    """``robotsim run``: simulate, localise, summarise, record; returns the exit status."""
    from scenarios.recording import write_recording
    from scenarios.runner import run_scenario
    from scenarios.spec import load_scenario

    if Path(args.scenario).is_dir():
        raise ScenarioError(args.scenario, None, "is a folder, not a scenario file")
    spec = with_run_options(load_scenario(args.scenario), args.seed, args.duration)
    stem = f"{spec.name}-seed{spec.run.seed}"
    rrd_path = args.rrd or DEFAULT_RUNS_DIR / f"{stem}.rrd"
    summary_path = args.summary or DEFAULT_RUNS_DIR / f"{stem}.json"

    _check_destinations(rrd_path, summary_path, scenario_inputs(args.scenario))
    extra = [args.sensor_log] if args.sensor_log else []
    for path in extra:
        reason = outputs.check_destination(path)
        if reason is not None or path.resolve() in (rrd_path.resolve(), summary_path.resolve()):
            raise ScenarioError(None, "--sensor-log", reason or "same file as another output")

    bar = ProgressBar(sys.stderr, label=stem) if sys.stderr.isatty() else None
    start = time.perf_counter()
    try:
        result = run_scenario(
            spec, progress=(lambda done: bar.update(RUN_SHARE * done)) if bar else None
        )
        with outputs.atomic_paths(rrd_path, summary_path, *extra) as (
            rrd_tmp,
            summary_tmp,
            *log_tmp,
        ):
            if log_tmp:
                from scenarios.sensor_log import write_sensor_log

                write_sensor_log(log_tmp[0], spec, result.log)
            recording_start = time.perf_counter()
            write_recording(rrd_tmp, spec, result.log, result.estimation)
            recording_s = time.perf_counter() - recording_start
            if bar:
                bar.update(1.0)
            summary = result.summary_with_timing(
                recording_s=recording_s, wall_s=time.perf_counter() - start
            )
            outputs.write_json(summary_tmp, summary)
    finally:
        if bar:
            bar.close()
    if args.spawn or args.connect is not None:
        from scenarios.recording import stream_recording, viewer_url

        stream_recording(
            spec,
            result.log,
            result.estimation,
            spawn=args.spawn,
            connect_url=viewer_url(args.connect),
        )
    timing = summary["timing"]
    rmse = summary["rmse_position_m"]
    figures = (
        f"containment {summary['containment']}, position RMSE UKF-only {rmse['ukf_only']:.3f} m, "
        f"fused {rmse['fused']:.3f} m"
        if "fused" in rmse
        else f"MCL position RMSE {rmse['mcl']:.3f} m"
    )
    print(
        f"{spec.name}: {spec.run.duration_s:g} s simulated and localised in {timing['wall_s']:.2f} s "
        f"({timing['realtime_factor']:.0f}x real time); {figures}; wrote {rrd_path} and {summary_path}"
    )
    failure = guarantee_failure(spec, summary)
    if failure:
        print(f"robotsim: {failure}", file=sys.stderr)
        return 1
    return 0


def with_run_options(
    spec: ScenarioSpec, seed: int | None, duration_s: float | None
) -> ScenarioSpec:
    """``spec`` with the ``--seed`` and ``--duration`` given on the command line (None: the
    scenario's); a value out of bounds is blamed on its option."""
    try:
        return spec.with_run(seed=seed, duration_s=duration_s)
    except ScenarioError as exc:
        raise ScenarioError(None, RUN_OPTIONS.get(exc.key or "", exc.key), exc.reason) from None


def guarantee_failure(spec: ScenarioSpec, summary: dict[str, Any]) -> str | None:
    """Why the run broke its guarantee, or None.

    With a sonar without faults (``outlier_prob = lost_echo_prob = 0``) every interval set
    must hold the truth; a containment below 1 there is a defect, not bad luck. With faults
    configured, more than ``q_max`` outliers in a scan may legitimately lose the truth; so
    may a world that differs from the map, a kidnapping or failed sonars
    (``ScenarioSpec.injected_faults``).
    """
    sonar = spec.sensors.sonar
    if (
        sonar.outlier_prob > 0.0
        or sonar.lost_echo_prob > 0.0
        or spec.injected_faults
        or "containment" not in summary
    ):
        return None  # faults configured or injected, or no interval sets (the particle filter)
    containment, empty = summary["containment"], summary["empty_epochs"]
    broken = []
    if containment is not None and containment < 1.0:
        broken.append(f"the truth left the interval set (containment {containment:.4g})")
    if empty:
        status = summary["epoch_status"]
        broken.append(
            f"{empty} epoch(s) found no set ({status['inconsistent']} inconsistent, "
            f"{status['lost']} lost) although the truth fits every scan"
        )
    if not broken:
        return None
    return (
        f"the guarantee failed: {'; '.join(broken)}, "
        f"although {spec.source}'s sonar has no faults configured"
    )


def scenario_inputs(name_or_path: str | Path) -> list[Path]:
    """The files a scenario reads: the scenario file and the map file it names (none for
    a built-in). Read only to protect them from being written over."""
    if str(name_or_path) in builtin_names():
        return []
    path = Path(name_or_path)
    inputs = [path]
    try:
        map_file = tomllib.loads(path.read_text(encoding="utf-8")).get("map", {}).get("file")
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError, AttributeError):
        return inputs  # the loader has reported (or will report) what is wrong
    if isinstance(map_file, str):
        inputs.append(path.parent / map_file)
    return inputs


def _check_destinations(rrd_path: Path, summary_path: Path, inputs: list[Path]) -> None:
    """Refuse, before any simulation, outputs that could not both be written or that would
    write over an input of the run."""
    for option, path in (("--rrd", rrd_path), ("--summary", summary_path)):
        reason = outputs.check_destination(path, inputs)
        if reason is not None:
            raise ScenarioError(None, option, reason)
    if rrd_path.resolve() == summary_path.resolve():
        raise ScenarioError(None, "--summary", "same file as --rrd")


def check_reproduce(args: argparse.Namespace) -> None:
    """Refuse, before a reproduction runs, an ``--out`` it may not replace and Monte Carlo
    sizes whose arrays could not fit in memory."""
    runs, steps = getattr(args, "runs", None), getattr(args, "steps", None)
    if runs is not None and runs > MAX_RUNS:
        raise ScenarioError(None, "--runs", f"must be at most {MAX_RUNS}, got {runs}")
    if runs is not None and steps is not None and runs * steps > MAX_RUN_STEPS:
        raise ScenarioError(
            None,
            "--steps",
            f"--runs x --steps must be at most {MAX_RUN_STEPS:.0e}, got {runs} x {steps}",
        )
    reason = outputs.check_folder_destination(args.out)
    if reason is not None:
        raise ScenarioError(None, "--out", reason)


def list_scenarios(args: argparse.Namespace) -> int:
    """``robotsim scenarios``: one line per built-in scenario, with its description."""
    names = builtin_names()
    width = max(map(len, names))
    for name in names:
        print(f"{name:<{width}}  {builtin_description(name)}")
    return 0


class ProgressBar:
    """A one-line progress bar redrawn in place on a terminal stream."""

    WIDTH = 30

    def __init__(self, stream: TextIO, label: str):
        self._stream = stream
        self._label = label
        self._shown = -1

    def update(self, fraction: float) -> None:
        """Show ``fraction`` (0 to 1) of the run done; redraws only when the bar changes."""
        percent = int(100 * min(max(fraction, 0.0), 1.0))
        if percent == self._shown:
            return
        self._shown = percent
        filled = percent * self.WIDTH // 100
        self._stream.write(
            f"\r{self._label} [{'#' * filled}{'.' * (self.WIDTH - filled)}] {percent:3d}%"
        )
        self._stream.flush()

    def close(self) -> None:
        """End the bar's line."""
        self._stream.write("\n")
        self._stream.flush()
