"""The sensor log of a run: what the robot sensed, in a documented columnar file (Parquet).

``robotsim run --sensor-log PATH`` writes it; ``robotsim replay LOG [--estimation FILE]``
runs the online localiser on it without the simulator, so data from a real robot in this
format can be localised too. The file holds one row per odometry sample, in time order:

``t_s`` (float64)
    Sample time, seconds, on a regular grid at the scenario's ``run.rate_hz``.
``ticks_left``, ``ticks_right`` (int64)
    Encoder tick increments since the previous sample (the first row's are unused).
``gyro_rad_s``, ``accel_x_m_s2``, ``accel_y_m_s2`` (float64)
    Yaw rate and planar specific force, body frame.
``sonar_range_m`` (list of float64, null on the samples without a scan)
    The scan taken at the sample, one reading per sonar of the belt (``inf``: no echo).
``true_x_m``, ``true_y_m``, ``true_theta_rad`` (float64, optional), ``kidnapped`` (bool, optional)
    The truth, when the data come from the simulator: the replay then scores its estimate.

The file's metadata key ``robotsim.scenario`` holds the scenario the robot ran (its TOML
tables as JSON: map, robot, sensors, start pose, ``[estimation]``), ``robotsim.scenario_dir`` the folder its map
files are relative to. Replaying a run's own log gives the estimation figures of its summary.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import tomllib
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from scenarios import outputs
from scenarios.errors import ScenarioError

if TYPE_CHECKING:  # pyarrow, the scenarios and the estimators are imported where used, so
    # that ``robotsim replay --help`` starts without them (and without numba)
    from robotsim.simulation import SimulationLog
    from scenarios.spec import ScenarioSpec

#: Metadata keys of the file.
SCENARIO_KEY = b"robotsim.scenario"
SCENARIO_DIR_KEY = b"robotsim.scenario_dir"
NAME_KEY = b"robotsim.name"
SENSOR_COLUMNS = ("t_s", "ticks_left", "ticks_right", "gyro_rad_s", "accel_x_m_s2", "accel_y_m_s2")
TRUTH_COLUMNS = ("true_x_m", "true_y_m", "true_theta_rad")


def scenario_tables(spec: ScenarioSpec) -> dict[str, Any]:
    """The tables of ``spec``'s file with its run's seed and duration (what the log ran)."""
    data = tomllib.loads(Path(spec.source).read_text(encoding="utf-8"))
    data.setdefault("run", {}).update(seed=spec.run.seed, duration_s=spec.run.duration_s)
    return data


def write_sensor_log(path: Path, spec: ScenarioSpec, log: SimulationLog) -> None:
    """Write ``log``'s sensor data and truth to the Parquet file ``path`` (format above)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    scans: list[list[float] | None] = [None] * len(log.t_s)
    at_sample = np.searchsorted(log.t_s, log.sonar_t_s - 0.5 / log.rate_hz)
    for sample, readings in zip(at_sample, log.sonar_range_m, strict=True):
        scans[int(sample)] = readings.tolist()
    kidnapped = np.isin(np.arange(len(log.t_s)), np.searchsorted(log.t_s, log.kidnap_t_s))
    table = pa.table(
        {
            "t_s": log.t_s,
            "ticks_left": log.wheel_ticks[:, 0],
            "ticks_right": log.wheel_ticks[:, 1],
            "gyro_rad_s": log.gyro_rad_s,
            "accel_x_m_s2": log.accel_m_s2[:, 0],
            "accel_y_m_s2": log.accel_m_s2[:, 1],
            "sonar_range_m": pa.array(scans, type=pa.list_(pa.float64())),
            "true_x_m": log.pose[:, 0],
            "true_y_m": log.pose[:, 1],
            "true_theta_rad": log.pose[:, 2],
            "kidnapped": kidnapped,
        }
    ).replace_schema_metadata(
        {
            SCENARIO_KEY: json.dumps(scenario_tables(spec)).encode(),
            SCENARIO_DIR_KEY: str(Path(spec.source).resolve().parent).encode(),
            NAME_KEY: spec.name.encode(),
        }
    )
    pq.write_table(table, path)


@dataclasses.dataclass(frozen=True, eq=False)
class SensorRecord:
    """A sensor log read back: the arrays the pipeline reads (names as in
    :class:`robotsim.simulation.SimulationLog`); ``pose`` and ``sonar_pose`` are NaN without
    truth columns."""

    t_s: np.ndarray
    wheel_ticks: np.ndarray
    gyro_rad_s: np.ndarray
    accel_m_s2: np.ndarray
    sonar_t_s: np.ndarray
    sonar_range_m: np.ndarray
    pose: np.ndarray
    sonar_pose: np.ndarray
    kidnap_t_s: np.ndarray
    rate_hz: float


def read_sensor_log(
    path: Path, estimation_file: Path | None = None
) -> tuple[ScenarioSpec, SensorRecord]:
    """The scenario and the data of the log at ``path`` (``estimation_file``: a TOML file
    whose ``[estimation]`` table replaces the scenario's).

    Raises:
        ScenarioError: an unreadable file, a missing column or metadata key, a scan of the
            wrong length, an estimation file with other tables (naming file and key).
    """
    import pyarrow as pa
    import pyarrow.parquet as pq

    from scenarios.spec import scenario_from_tables

    source = str(path)
    try:
        table = pq.read_table(path)
    except (OSError, pa.ArrowException) as exc:
        raise ScenarioError(source, None, f"not a readable Parquet sensor log: {exc}") from None
    metadata = table.schema.metadata or {}
    if SCENARIO_KEY not in metadata:
        raise ScenarioError(source, SCENARIO_KEY.decode(), "missing from the file's metadata")
    for name in (*SENSOR_COLUMNS, "sonar_range_m"):
        if name not in table.column_names:
            raise ScenarioError(source, name, "missing column")
    try:
        data = json.loads(metadata[SCENARIO_KEY].decode())
    except ValueError as exc:
        raise ScenarioError(source, SCENARIO_KEY.decode(), f"not valid JSON: {exc}") from None
    spec_source = source
    if estimation_file is not None:
        spec_source = str(estimation_file)
        try:
            override = tomllib.loads(Path(estimation_file).read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
            raise ScenarioError(spec_source, None, f"cannot read: {exc}") from None
        other = sorted(set(override) - {"estimation"})
        if other:
            raise ScenarioError(spec_source, other[0], "only an [estimation] table may be given")
        data["estimation"] = override.get("estimation", {})
    base_dir = Path(metadata.get(SCENARIO_DIR_KEY, b".").decode())
    name = metadata.get(NAME_KEY, Path(path).stem.encode()).decode()
    spec = scenario_from_tables(data, source=spec_source, base_dir=base_dir, name=name)
    columns = {name: table.column(name).to_numpy() for name in SENSOR_COLUMNS}
    scans = table.column("sonar_range_m").to_pylist()
    at_scan = np.array([i for i, scan in enumerate(scans) if scan is not None], dtype=np.int64)
    belt = spec.sensors.sonar.count
    for i in at_scan:
        if len(scans[i]) != belt:
            raise ScenarioError(
                source, f"sonar_range_m[{i}]", f"has {len(scans[i])} readings, the belt {belt}"
            )
    t_s = columns["t_s"].astype(np.float64)
    if all(name in table.column_names for name in TRUTH_COLUMNS):
        pose = np.column_stack([table.column(name).to_numpy() for name in TRUTH_COLUMNS])
    else:
        pose = np.full((len(t_s), 3), np.nan)
    kidnapped = (
        table.column("kidnapped").to_numpy(zero_copy_only=False).astype(bool)
        if "kidnapped" in table.column_names
        else np.zeros(len(t_s), dtype=bool)
    )
    record = SensorRecord(
        t_s=t_s,
        wheel_ticks=np.column_stack([columns["ticks_left"], columns["ticks_right"]]).astype(
            np.int64
        ),
        gyro_rad_s=columns["gyro_rad_s"].astype(np.float64),
        accel_m_s2=np.column_stack([columns["accel_x_m_s2"], columns["accel_y_m_s2"]]),
        sonar_t_s=t_s[at_scan],
        sonar_range_m=np.array([scans[i] for i in at_scan], dtype=np.float64).reshape(
            len(at_scan), belt
        ),
        pose=pose,
        sonar_pose=pose[at_scan],
        kidnap_t_s=t_s[kidnapped],
        rate_hz=spec.run.rate_hz,
    )
    return spec, record


def replay(path: Path, estimation_file: Path | None = None) -> dict[str, Any]:
    """The localiser run on the log at ``path``: the estimation figures of the summary."""
    from scenarios.mcl_pipeline import Estimator, estimate_mcl, mcl_summary
    from scenarios.pipeline import estimate, estimation_summary

    spec, record = read_sensor_log(path, estimation_file)
    if spec.estimation.estimator == Estimator.MCL:
        figures = mcl_summary(record, estimate_mcl(spec, record))
    else:
        figures = estimation_summary(record, estimate(spec, record)[0])
    return {
        "scenario": spec.name,
        "samples": len(record.t_s),
        "scans": len(record.sonar_t_s),
        "estimator": str(spec.estimation.estimator),
        **figures,
    }


def add_replay_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``robotsim replay``."""
    parser.add_argument("log", type=Path, metavar="LOG", help="a sensor log (Parquet)")
    parser.add_argument(
        "--estimation",
        type=Path,
        metavar="FILE",
        help="a TOML file whose [estimation] table replaces the log's",
    )
    parser.add_argument(
        "--summary", type=Path, metavar="PATH", help="write the figures as JSON (default: stdout)"
    )


def replay_command(args: argparse.Namespace) -> int:
    """``robotsim replay``: the localiser on a sensor log; prints or writes its figures."""
    if args.summary is not None:
        reason = outputs.check_destination(args.summary)
        if reason is not None:
            raise ScenarioError(None, "--summary", reason)
    figures = replay(args.log, args.estimation)
    if args.summary is None:
        print(json.dumps(figures, indent=2))
        return 0
    with outputs.atomic_path(args.summary) as tmp:
        outputs.write_json(tmp, figures)
    print(f"{args.log}: replayed; wrote {args.summary}")
    return 0
