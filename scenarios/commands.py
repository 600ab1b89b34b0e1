"""The ``run`` and ``scenarios`` sub-commands of ``robotsim`` (``scenarios.cli`` wires them).

``robotsim run [SCENARIO] [--rrd PATH] [--summary PATH] [--seed N] [--duration S]`` runs one
scenario headless and writes its rerun recording and its JSON summary, both atomically: a
user error or a crash leaves neither file behind (nor a half of one). Both destinations are
checked before anything runs. The run checks its own guarantee: exit status 1 when the
truth left an interval set although the sonar has no faults configured.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any, TextIO

from scenarios import outputs
from scenarios.errors import ScenarioError
from scenarios.spec import DEFAULT_MAP, ScenarioSpec, builtin_names, load_scenario

#: Where ``robotsim run`` writes when no path is given.
DEFAULT_RUNS_DIR = Path("runs")

#: The options of ``robotsim run`` that override a key of the scenario's ``[run]``.
RUN_OPTIONS = {"run.seed": "--seed", "run.duration_s": "--duration"}

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


def run(args: argparse.Namespace) -> int:
    """``robotsim run``: simulate, localise, summarise, record; returns the exit status."""
    from scenarios.recording import write_recording
    from scenarios.runner import run_scenario

    spec = with_run_options(load_scenario(args.scenario), args.seed, args.duration)
    stem = f"{spec.name}-seed{spec.run.seed}"
    rrd_path = args.rrd or DEFAULT_RUNS_DIR / f"{stem}.rrd"
    summary_path = args.summary or DEFAULT_RUNS_DIR / f"{stem}.json"

    _check_destinations(rrd_path, summary_path)
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
    timing = summary["timing"]
    rmse = summary["rmse_position_m"]
    print(
        f"{spec.name}: {spec.run.duration_s:g} s simulated and localised in {timing['wall_s']:.2f} s "
        f"({timing['realtime_factor']:.0f}x real time); containment {summary['containment']}, position RMSE "
        f"UKF-only {rmse['ukf_only']:.3f} m, fused {rmse['fused']:.3f} m; wrote {rrd_path} and {summary_path}"
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
    configured, more than ``q_max`` outliers in a scan may legitimately lose the truth.
    """
    sonar = spec.sensors.sonar
    containment = summary["containment"]
    if (
        sonar.outlier_prob > 0.0
        or sonar.lost_echo_prob > 0.0
        or containment is None
        or containment >= 1.0
    ):
        return None
    return (
        f"the guarantee failed: the truth left the interval set (containment {containment:.4g}) "
        f"although {spec.source}'s sonar has no faults configured"
    )


def _check_destinations(rrd_path: Path, summary_path: Path) -> None:
    """Refuse, before any simulation, outputs that could not both be written."""
    for option, path in (("--rrd", rrd_path), ("--summary", summary_path)):
        reason = outputs.check_destination(path)
        if reason is not None:
            raise ScenarioError(None, option, reason)
    if rrd_path.resolve() == summary_path.resolve():
        raise ScenarioError(None, "--summary", "same file as --rrd")


def list_scenarios(args: argparse.Namespace) -> int:
    """``robotsim scenarios``: one line per built-in scenario, with its description."""
    names = builtin_names()
    width = max(map(len, names))
    for name in names:
        print(f"{name:<{width}}  {load_scenario(name).description}")
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
