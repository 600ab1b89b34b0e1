"""Paper 001 in simulation: CV, CTRV, CTRA and CCA in a UKF fusing GPS and odometry.

    robotsim reproduce motion-models [--runs N] [--out DIR] [--seed S] [--duration S]

For each drive (urban, highway; :mod:`robotsim.vehicle.drives`) and each model
(:mod:`localization.motion_models`), a UKF with augmented process noise (paper 001
section III-C, table I) fuses odometry (speed and yaw rate, 10 Hz; CV uses the speed only,
as the paper compares CV and CTRV on "modelling the yaw rate and using it as an
observation") and GPS (1 Hz). All models see the same sensor draws and the same initial
errors (common random numbers). Errors against the exact reference at the odometry epochs,
after a warm-up of ``WARM_UP_S``: Euclidean, lateral and longitudinal (in the reference
heading frame) RMS over all runs and epochs, and the Euclidean RMS restricted to epochs
with a high yaw rate (``|omega| > 2 deg/s``) and a high acceleration (``|a| > 0.5 m/s^2``).

Writes ``DIR/table.json``, ``DIR/table.md`` (like table II, with the paper's values beside),
and ``DIR/fig5_cv_ctrv_highway.png``, ``DIR/fig6_ctrv_ctra_highway.png``,
``DIR/fig7_ctra_cca_urban.png`` (Euclidean error over time, like figures 5-7) and
``DIR/drives.png`` (the reference drives).

Choices where the paper is silent (documented in ``table.md`` too):

- sigma points: scaled, ``alpha = 1e-5``, ``beta = 2``, ``kappa = 3 - L`` (paper 001
  footnote 5), ``L`` the augmented dimension in the prediction. The centre weight is then
  about ``-2e10``; the UKF (:mod:`localization.sigma_points`) takes its sums about the
  centre point so that weight never multiplies anything, and this module runs every step in
  a local frame centred on the current position estimate: the second differences the UKF
  divides by ``gamma^2 ~ 3e-10`` are then taken between numbers of metres, not of
  kilometres, so rounding stays below a micrometre instead of centimetres per step.
- process noise: table I read as random-walk intensities (``localization.motion_models``).
- initial belief: the true initial state plus a draw from the initial covariance
  ``INITIAL_STD``, the same draw for every model.
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import asdict, dataclass, replace

import numpy as np

from localization.gaussian import Gaussian
from localization.models import MeasurementModel, ProcessNoise
from localization.motion_models import MODELS, MotionModel, gps_model
from localization.sigma_points import ScaledSigmaPoints
from localization.ukf import UnscentedKalmanFilter
from robotsim.vehicle.drives import DRIVES
from robotsim.vehicle.sensors import VehicleMeasurements, VehicleSensorParams, measure
from robotsim.vehicle.single_track import ReferenceDrive
from scenarios.errors import ScenarioError
from scenarios.outputs import atomic_directory, write_json, write_text
from scenarios.reproduce._filter_runs import (
    MAGNITUDE_FACTOR,
    format_ratio,
    magnitude_verdict,
)
from scenarios.reproduce.figure_style import axis_label, plain_ticks, save
from scenarios.warmup import no_compilation

HELP = (
    "paper 001: CV, CTRV, CTRA, CCA in a GPS + odometry UKF on simulated urban and highway drives"
)

#: Paper 001 footnote 5.
SIGMA_POINTS = ScaledSigmaPoints(alpha=1e-5, beta=2.0, kappa=None)
#: Epochs before this time are left out of the error statistics (filter transient).
WARM_UP_S = 10.0
#: The restricted comparisons of figures 5 and 6.
HIGH_YAW_RATE_RAD_S = math.radians(2.0)
HIGH_ACCEL_M_S2 = 0.5
#: Standard deviations of the initial belief, by state name (GPS-sized position error).
INITIAL_STD = {
    "x_m": 1.5,
    "y_m": 1.5,
    "theta_rad": 0.1,
    "v_m_s": 0.5,
    "vx_m_s": 0.5,
    "vy_m_s": 0.5,
    "a_m_s2": 0.5,
    "omega_rad_s": 0.05,
    "c_1_m": 0.01,
}
#: Paper 001 table II (RMS in metres), for the side-by-side table.
PAPER_TABLE_II = {
    "urban": {
        "CV": (3.17, 2.32, 2.16),
        "CTRV": (2.36, 1.76, 1.58),
        "CTRA": (1.85, 1.31, 1.31),
        "CCA": (2.49, 1.68, 1.84),
    },
    "highway": {
        "CV": (3.89, 1.67, 3.52),
        "CTRV": (3.98, 1.52, 3.68),
        "CTRA": (3.35, 1.35, 3.07),
        "CCA": (3.36, 1.35, 3.08),
    },
}
ERROR_KINDS = ("euclidean", "lateral", "longitudinal")
#: The entries of the results written to ``table.json``.
PUBLIC_KEYS = (
    "settings",
    "table",
    "restricted_euclidean",
    "cost_us_per_run_step",
    "findings",
    "against_paper",
)
#: A model "beats" another when its RMS error is at least this fraction smaller.
FINDING_MARGIN = 0.05
#: The pairs of figures 5-7: (figure file, drive, models, restriction).
FIGURES = (
    ("fig5_cv_ctrv_highway.png", "highway", ("CV", "CTRV"), "high_yaw_rate"),
    ("fig6_ctrv_ctra_highway.png", "highway", ("CTRV", "CTRA"), "high_acceleration"),
    ("fig7_ctra_cca_urban.png", "urban", ("CTRA", "CCA"), None),
)


@dataclass(frozen=True)
class ModelRun:
    """One model's filter on ``R`` runs of one drive (``K`` epochs)."""

    position_m: np.ndarray  # (R, K, 2) estimated positions after the updates
    seconds: float  # wall time of the whole filter loop, after an untimed warm-up on its start


def initial_state(model: MotionModel, drive: ReferenceDrive) -> np.ndarray:
    """The true state ``(n,)`` of ``model`` at the drive's first sample."""
    x, y, heading = drive.pose[0]
    v, a, omega = drive.speed_m_s[0], drive.accel_m_s2[0], drive.yaw_rate_rad_s[0]
    values = {
        "x_m": x,
        "y_m": y,
        "theta_rad": heading,
        "v_m_s": v,
        "a_m_s2": a,
        "omega_rad_s": omega,
        "vx_m_s": v * math.cos(heading),
        "vy_m_s": v * math.sin(heading),
        "c_1_m": float(drive.curvature_1_m[0]),
    }
    return np.array([values[name] for name in model.state_names])


def run_filter(
    model: MotionModel,
    drive: ReferenceDrive,
    meas: VehicleMeasurements,
    draws: np.ndarray,
    points: ScaledSigmaPoints = SIGMA_POINTS,
) -> ModelRun:
    """The UKF of ``model`` on every run of ``meas``; ``draws (R, >= n)`` standard normals
    give the initial errors (``INITIAL_STD``). One batched filter over the runs."""
    runs, epochs = meas.speed_m_s.shape
    dt_s = 1.0 / meas.params.odometry_rate_hz
    ukf = UnscentedKalmanFilter(points=points)
    # the models' compiled kernels: the UKF's compiled path for the prediction and the GPS update
    process = model.process_model(
        np.diag(model.process_noise_std(dt_s) ** 2), noise=ProcessNoise.AUGMENTED
    )
    gps = gps_model(meas.params.gps_noise_std_m**2 * np.eye(2))
    readings = {"speed": meas.speed_m_s, "yaw_rate": meas.yaw_rate_rad_s}  # (R, K) each
    noise_std = {
        "speed": meas.params.speed_noise_std_m_s,
        "yaw_rate": meas.params.yaw_rate_noise_std_rad_s,
    }
    odometry = MeasurementModel(
        h=model.odometry, R=np.diag([noise_std[name] ** 2 for name in model.odometry_names])
    )
    odo_z = np.stack([readings[name] for name in model.odometry_names], axis=-1)  # (R, K, m)
    std0 = np.array([INITIAL_STD[name] for name in model.state_names])
    mean = initial_state(model, drive) + std0 * draws[:, : model.n]
    belief = Gaussian(
        mean, np.broadcast_to(np.diag(std0**2), (runs, model.n, model.n)), model.angle_indices
    )
    out = np.empty((runs, epochs, 2))

    def filter_epochs(belief: Gaussian, count: int) -> None:
        """The filter over the first ``count`` epochs, positions into ``out``."""
        gps_k = 0
        for k in range(count):
            # local frame centred on the current position estimate (see the module docstring)
            origin = belief.mean[:, :2].copy()
            local = belief.mean.copy()
            local[:, :2] -= origin
            belief = Gaussian.trusted(local, belief.cov, model.angle_indices)
            if k > 0:
                belief = ukf.predict(belief, process, dt_s)
            belief = ukf.update(belief, odo_z[:, k], odometry)
            if meas.gps_epoch[k]:
                belief = ukf.update(belief, meas.gps_xy_m[:, gps_k] - origin, gps)
                gps_k += 1
            mean = belief.mean.copy()
            mean[:, :2] += origin
            belief = Gaussian.trusted(mean, belief.cov, model.angle_indices)
            out[:, k] = mean[:, :2]

    # Untimed, the epochs up to the first GPS fix (a prediction, both updates): numba builds
    # or loads the compiled steps here, so that the cost table counts no compile time.
    first_fix = int(np.argmax(meas.gps_epoch)) if meas.gps_epoch.any() else epochs
    filter_epochs(belief, min(epochs, max(2, first_fix + 1)))
    with no_compilation(f"the cost of the {model.name} filter"):
        start = time.perf_counter()
        filter_epochs(belief, epochs)
        seconds = time.perf_counter() - start
    return ModelRun(position_m=out, seconds=seconds)


def position_errors(
    estimate_m: np.ndarray, drive: ReferenceDrive, meas: VehicleMeasurements
) -> dict[str, np.ndarray]:
    """Per-run, per-epoch errors ``(R, K)``: euclidean, lateral (left), longitudinal (forward)."""
    ref = drive.pose[meas.drive_index]  # (K, 3)
    err = estimate_m - ref[:, :2]
    cos_h, sin_h = np.cos(ref[:, 2]), np.sin(ref[:, 2])
    return {
        "euclidean": np.hypot(err[..., 0], err[..., 1]),
        "lateral": -sin_h * err[..., 0] + cos_h * err[..., 1],
        "longitudinal": cos_h * err[..., 0] + sin_h * err[..., 1],
    }


def rms(values: np.ndarray, epochs: np.ndarray) -> float | None:
    """RMS of ``values (R, K)`` over all runs and the selected epochs ``(K,)`` bool; None if none."""
    return float(np.sqrt(np.mean(np.square(values[:, epochs])))) if epochs.any() else None


def experiment(
    runs: int, seed: int, duration_s: float, sensors: VehicleSensorParams | None = None
) -> dict:
    """Run the whole comparison (no I/O). Returns the results and, under ``"series"``, the
    per-epoch RMS-over-runs Euclidean errors and masks the figures need."""
    sensors = sensors or VehicleSensorParams()
    drive_seed, sensor_seed, init_seed = np.random.SeedSequence(seed).spawn(3)
    draws = np.random.default_rng(init_seed).standard_normal((runs, 6))
    table: dict = {}
    restricted: dict = {}
    cost: dict = {}
    series: dict = {}
    drives: dict = {}
    for offset, (drive_name, make_drive) in enumerate(DRIVES.items()):
        drive = make_drive(
            np.random.default_rng([*drive_seed.generate_state(2), offset]), duration_s
        )
        meas = measure(
            drive, sensors, np.random.default_rng([*sensor_seed.generate_state(2), offset]), runs
        )
        settled = meas.t_s >= WARM_UP_S
        masks = {
            "all": settled,
            "high_yaw_rate": settled
            & (np.abs(drive.yaw_rate_rad_s[meas.drive_index]) > HIGH_YAW_RATE_RAD_S),
            "high_acceleration": settled
            & (np.abs(drive.accel_m_s2[meas.drive_index]) > HIGH_ACCEL_M_S2),
        }
        table[drive_name], restricted[drive_name], cost[drive_name] = {}, {}, {}
        series[drive_name] = {"t_s": meas.t_s, "masks": masks, "euclidean": {}}
        drives[drive_name] = drive
        for model_name, model in MODELS.items():
            result = run_filter(model, drive, meas, draws)
            errors = position_errors(result.position_m, drive, meas)
            table[drive_name][model_name] = {
                kind: rms(errors[kind], settled) for kind in ERROR_KINDS
            }
            restricted[drive_name][model_name] = {
                name: rms(errors["euclidean"], masks[name])
                for name in ("high_yaw_rate", "high_acceleration")
            }
            cost[drive_name][model_name] = 1e6 * result.seconds / (runs * meas.t_s.size)
            series[drive_name]["euclidean"][model_name] = np.sqrt(
                np.mean(np.square(errors["euclidean"]), axis=0)
            )
        restricted[drive_name]["epochs"] = {name: int(mask.sum()) for name, mask in masks.items()}
    return {
        "settings": {
            "runs": runs,
            "seed": seed,
            "duration_s": duration_s,
            "warm_up_s": WARM_UP_S,
            "sigma_points": {
                "alpha": SIGMA_POINTS.alpha,
                "beta": SIGMA_POINTS.beta,
                "kappa": "3 - L",
            },
            "process_noise_intensity": {
                m.name: dict(zip(m.noise_names, m.noise_intensity, strict=True))
                for m in MODELS.values()
            },
            "sensors": asdict(sensors),
            "initial_std": INITIAL_STD,
            "high_yaw_rate_deg_s": math.degrees(HIGH_YAW_RATE_RAD_S),
            "high_acceleration_m_s2": HIGH_ACCEL_M_S2,
        },
        "table": table,
        "restricted_euclidean": restricted,
        "cost_us_per_run_step": cost,
        "findings": findings(table, restricted),
        "against_paper": against_paper(table),
        "series": series,
        "drives": drives,
    }


def _smaller(a: float | None, b: float | None, margin: float = 0.0) -> bool | None:
    """``a < (1 - margin) b``, None when a subset was empty."""
    return None if a is None or b is None else a < (1.0 - margin) * b


def findings(table: dict, restricted: dict) -> dict[str, dict[str, bool | None]]:
    """The paper's qualitative findings checked on the numbers, per drive (None: no epochs).

    "Beats" asks for an error at least ``FINDING_MARGIN`` smaller, so that a difference of
    a few millimetres does not count as a finding.
    """
    out = {}
    for drive, row in table.items():
        eu = {m: row[m]["euclidean"] for m in row}
        r = restricted[drive]
        out[drive] = {
            "curvilinear_beat_cv": all(
                _smaller(eu[m], eu["CV"], FINDING_MARGIN) for m in ("CTRV", "CTRA", "CCA")
            ),
            "ctrv_beats_cv_at_high_yaw_rate": _smaller(
                r["CTRV"]["high_yaw_rate"], r["CV"]["high_yaw_rate"], FINDING_MARGIN
            ),
            "ctra_beats_ctrv": _smaller(eu["CTRA"], eu["CTRV"], FINDING_MARGIN),
            "ctra_beats_ctrv_at_high_acceleration": _smaller(
                r["CTRA"]["high_acceleration"], r["CTRV"]["high_acceleration"], FINDING_MARGIN
            ),
            "cca_within_10_percent_of_ctra": abs(eu["CCA"] - eu["CTRA"]) <= 0.1 * eu["CTRA"],
        }
    return out


def against_paper(table: dict) -> dict:
    """Our RMS over the paper's table II, by drive, model and error kind, with the magnitude
    verdicts and one summary line per drive (how many within the factor, the farthest)."""
    ratios = {
        drive: {
            m: {
                kind: row[m][kind] / PAPER_TABLE_II[drive][m][i]
                for i, kind in enumerate(ERROR_KINDS)
            }
            for m in row
        }
        for drive, row in table.items()
    }
    summary = []
    for drive, by_model in ratios.items():
        cells = [(r, m, kind) for m, by_kind in by_model.items() for kind, r in by_kind.items()]
        close = sum(1 / MAGNITUDE_FACTOR <= r <= MAGNITUDE_FACTOR for r, _, _ in cells)
        worst, m, kind = max(cells, key=lambda c: max(c[0], 1.0 / c[0]))
        summary.append(
            f"{drive}: {close} of {len(cells)} within a factor {MAGNITUDE_FACTOR:g}; "
            f"farthest {m} {kind}: {magnitude_verdict(worst)}"
        )
    return {
        "paper_table_ii": {
            drive: {m: dict(zip(ERROR_KINDS, v, strict=True)) for m, v in row.items()}
            for drive, row in PAPER_TABLE_II.items()
        },
        "ratio_to_paper": ratios,
        "magnitude_verdict": {
            drive: {m: {k: magnitude_verdict(r) for k, r in v.items()} for m, v in row.items()}
            for drive, row in ratios.items()
        },
        "summary": summary,
    }


def table_markdown(results: dict) -> str:
    """``table.md``: table II side by side with the paper, restricted errors, cost, findings."""
    models = list(MODELS)
    s = results["settings"]
    lines = [
        "# Paper 001 reproduced in simulation: motion models in a GPS + odometry UKF",
        "",
        f"{s['runs']} Monte Carlo runs per drive, seed {s['seed']}, drives of {s['duration_s']:.0f} s, "
        f"errors after a {s['warm_up_s']:.0f} s warm-up. Each cell: our RMS (m), in brackets "
        "the paper's table II, then ours / paper.",
        "",
        "| scenario | RMS (m) | " + " | ".join(models) + " |",
        "|---|---|" + "---|" * len(models),
    ]
    ratios = results["against_paper"]["ratio_to_paper"]
    for drive, row in results["table"].items():
        for i, kind in enumerate(ERROR_KINDS):
            cells = [
                f"{row[m][kind]:.2f} ({PAPER_TABLE_II[drive][m][i]:.2f}) "
                f"{format_ratio(ratios[drive][m][kind])}"
                for m in models
            ]
            lines.append(f"| {drive if i == 0 else ''} | {kind} | " + " | ".join(cells) + " |")
    lines += ["", "Magnitudes against table II:", ""]
    lines += [f"- {line}" for line in results["against_paper"]["summary"]]
    lines += [
        "",
        "Euclidean RMS restricted to high yaw rate "
        f"(|omega| > {s['high_yaw_rate_deg_s']:.0f} deg/s) and high acceleration "
        f"(|a| > {s['high_acceleration_m_s2']} m/s^2), and the filter cost:",
        "",
        "| scenario | subset | epochs | " + " | ".join(models) + " |",
        "|---|---|---|" + "---|" * len(models),
    ]
    for drive, row in results["restricted_euclidean"].items():
        for subset in ("high_yaw_rate", "high_acceleration"):
            cells = ["n/a" if row[m][subset] is None else f"{row[m][subset]:.2f}" for m in models]
            lines.append(
                f"| {drive} | {subset} | {row['epochs'][subset]} | " + " | ".join(cells) + " |"
            )
        cost = results["cost_us_per_run_step"][drive]
        lines.append(
            f"| {drive} | cost (µs per run-step) | | "
            + " | ".join(f"{cost[m]:.1f}" for m in models)
            + " |"
        )
    lines += [
        "",
        f'Paper 001\'s findings, checked on these numbers ("beats": an RMS at least '
        f"{100 * FINDING_MARGIN:.0f} % smaller):",
        "",
    ]
    for drive, checks in results["findings"].items():
        for name, holds in checks.items():
            verdict = {True: "holds", False: "does NOT hold", None: "not evaluable (no epochs)"}[
                holds
            ]
            lines.append(f"- {drive}: {name.replace('_', ' ')}: {verdict}")
    lines += [
        "",
        "Choices: sigma points alpha = 1e-5, beta = 2, kappa = 3 - L (L the augmented dimension in",
        "the prediction); moments about the centre point and a local frame centred on the estimate",
        "keep the centre weight (about -2e10) harmless. Table I read as random-walk intensities per",
        "sqrt(s). CV uses GPS and speed; the others GPS, speed and yaw rate. Initial belief: the true",
        "state plus one draw from its covariance, shared by all models. Sensors: "
        + ", ".join(f"{k} = {v:.4g}" for k, v in s["sensors"].items())
        + ".",
        "",
    ]
    return "\n".join(lines)


def figures(results: dict) -> dict:
    """Figures 5-7 (Euclidean error over time of a pair of models, their difference below:
    CTRV and CTRA coincide to millimetres) and the bird's-eye view of the drives, by file
    name, unsaved."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = {}
    for filename, drive, pair, subset in FIGURES:
        data = results["series"][drive]
        fig, (ax, low) = plt.subplots(
            2, 1, figsize=(9, 5.0), sharex=True, gridspec_kw={"height_ratios": [2.2, 1.0]}
        )
        if subset is not None:
            for axes in (ax, low):
                axes.fill_between(
                    data["t_s"],
                    0,
                    1,
                    where=data["masks"][subset],
                    transform=axes.get_xaxis_transform(),
                    color="0.85",
                    label=subset.replace("_", " "),
                )
        for model in pair:
            restricted = results["restricted_euclidean"][drive][model]
            label = f"{model} (RMS {results['table'][drive][model]['euclidean']:.2f} m"
            if subset and restricted[subset] is not None:
                label += f", {restricted[subset]:.2f} m in subset"
            label += ")"
            ax.plot(data["t_s"], data["euclidean"][model], lw=0.8, label=label)
        first, second = pair
        gap = data["euclidean"][second] - data["euclidean"][first]
        low.plot(
            data["t_s"],
            gap,
            lw=0.8,
            color="k",
            label=f"{second} - {first} (largest |difference| {np.max(np.abs(gap)):.3g} m)",
        )
        for axes in (ax, low):
            plain_ticks(axes)
        ax.set_ylabel(axis_label("Euclidean error, RMS over runs", "m"))
        low.set_ylabel(axis_label("difference", "m"))
        low.set_xlabel(axis_label("time", "s"))
        number = filename[3]
        ax.set_title(f"paper 001 fig. {number}: {' vs '.join(pair)}, {drive} drive")
        ax.legend(loc="upper right", fontsize=8)
        low.legend(loc="upper right", fontsize=7)
        fig.tight_layout()
        out[filename] = fig
    fig, axes = plt.subplots(1, len(results["drives"]), figsize=(10, 5))
    for ax, (name, drive) in zip(np.atleast_1d(axes), results["drives"].items(), strict=True):
        ax.plot(drive.pose[:, 0], drive.pose[:, 1], lw=0.8, label="reference path")
        ax.plot(*drive.pose[0, :2], "o", color="tab:green", label="start")
        ax.set_aspect("equal")
        ax.set_title(f"{name} reference drive")
        ax.set_xlabel(axis_label("x", "m"))
        ax.set_ylabel(axis_label("y", "m"))
        ax.legend(loc="best", fontsize=8)
    fig.tight_layout()
    out["drives.png"] = fig
    return out


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``robotsim reproduce motion-models``."""
    parser.add_argument(
        "--runs", type=int, default=20, help="Monte Carlo runs per drive (default 20)"
    )
    parser.add_argument("--out", default="runs/reproduce/motion-models", help="output folder")
    parser.add_argument(
        "--seed", type=int, default=1, help="seed of the drives and sensor noise (default 1)"
    )
    parser.add_argument(
        "--duration", type=float, default=300.0, help="length of each drive in s (default 300)"
    )
    parser.add_argument(
        "--unbiased-odometry",
        action="store_true",
        help="sensitivity check: odometry without its speed-scale and yaw-rate biases",
    )


def main(args: argparse.Namespace) -> int:
    """Run the comparison and write ``table.json``, ``table.md`` and the figures."""
    if args.runs < 1:
        raise ScenarioError(None, "--runs", f"must be >= 1, got {args.runs}")
    if args.seed < 0:
        raise ScenarioError(None, "--seed", f"must be >= 0, got {args.seed}")
    if not (math.isfinite(args.duration) and args.duration >= 2.0 * WARM_UP_S):
        raise ScenarioError(
            None, "--duration", f"must be >= {2.0 * WARM_UP_S:.0f} s, got {args.duration}"
        )
    sensors = VehicleSensorParams()
    if args.unbiased_odometry:
        sensors = replace(sensors, speed_scale_error=0.0, yaw_rate_bias_rad_s=0.0)
    results = experiment(args.runs, args.seed, args.duration, sensors)
    with atomic_directory(args.out) as folder:
        write_json(folder / "table.json", {k: results[k] for k in PUBLIC_KEYS})
        write_text(folder / "table.md", table_markdown(results))
        for name, fig in figures(results).items():
            save(fig, folder / name)
    print(table_markdown(results))
    print(f"written to {args.out}")
    return 0
