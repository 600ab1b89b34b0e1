"""The rerun recording of one run: the map (y up), the truth, the sonar, the interval sets, both
estimates, and the time series, with one colour and name per kind of thing drawn.

Everything time-varying is sent in bulk with ``send_columns`` on one ``time`` timeline
(seconds since the start of the run): one call per entity, never one log call per sample.

How it reads (the default blueprint, :func:`default_blueprint`):

- the map view on the left, **y up** as in the project's figures: rerun's 2-D view has y
  down, so the ``world`` root carries a reflection ``y -> -y`` (``Transform3D``) and the view
  looks at ``/`` (its bounds, fixed from the map, are in that reflected frame);
- one ``AnnotationContext`` on ``world`` names and colours every kind of thing drawn
  (:data:`CLASSES`); the entities carry class ids, and a legend of the classes drawn sits
  under the map (``world/legend``);
- the truth and both estimates draw a **trail up to the time cursor** (the last
  :data:`TRAIL_WINDOW_S` seconds); their whole paths are a faint layer, hidden by default
  (tick it in the blueprint panel);
- line widths are in screen units (ui points), so thin lines stay thin when zoomed;
- the fused branch's outline is honest about the fusion rule: under the paper's clamp the
  covariance is never updated (``localization.fusion``: the clamp moves the mean only), so
  after its first clamp the fused branch shows the **box it was last clamped to** (the
  hull of the component used), not the UKF's covariance it still carries; the truncated
  rules do update the covariance, so their ellipse is the fused covariance;
- on the right, one tab of plots grouped by unit (position error m, heading error rad,
  set width m, set area m², epoch time ms, status and outliers as steps) and one tab of
  raw sensors (the last :data:`RAW_WINDOW_S` seconds before the cursor).

Entity paths (the tests read them back):

- ``world``: the y-up ``Transform3D`` and the ``AnnotationContext``, static;
- ``world/map/walls``: the map segments, static ``LineStrips2D``;
- ``world/legend``: one labelled point per class drawn, static ``Points2D``;
- ``world/obstacles/static``: the edges of the unmapped obstacles that stand still (``[world]
  obstacles``), static ``LineStrips2D``; ``world/obstacles/moving``: the edges of the moving
  ones at every ``ESTIMATE_STRIDE``-th sample, ``LineStrips2D`` (rows of e strips);
- ``world/robot/path``: the whole true trajectory, static faint ``LineStrips2D``;
- ``world/robot/trail``: one segment per ``TRAIL_STRIDE`` samples, ``LineStrips2D``, shown
  for the last ``TRAIL_WINDOW_S`` seconds up to the cursor;
- ``world/robot/footprint``: the true position with the footprint disk, ``Ellipses2D`` (N rows);
- ``world/robot/heading``: an arrow along the true heading, ``Arrows2D`` (N rows);
- ``world/sonar/cones``: each sensor's cone at each scan, out to the reading (or to ``d_max``
  when there is no echo, drawn fainter), ``LineStrips2D`` (M rows of k strips);
- ``world/sonar/echoes``: the point of each finite reading on its sensor's axis, ``Points2D``
  (M rows);
- ``sensors/encoders/left``, ``sensors/encoders/right``: ticks per sample, ``Scalars`` (N);
- ``sensors/gyro/rate_rad_s``: ``Scalars`` (N);
- ``sensors/accelerometer/x_m_s2``, ``.../y_m_s2``: body-frame specific force, ``Scalars`` (N);
- ``truth/v_m_s``, ``truth/omega_rad_s``: true body velocity, ``Scalars`` (N).

The localisation pipeline (when the run has an estimation):

- ``world/intervals/boxes``: the (x, y) projections of the outer boxes of each epoch, the
  inner ones in their own class, ``Boxes2D`` (E rows of K boxes);
- ``world/intervals/hull``: one hull per connected component of each epoch's outer set,
  ``Boxes2D`` (E rows; an inconsistent or lost epoch has none);
- ``world/estimates/<branch>/path``: static faint trajectories; ``.../trail``: as the truth's;
- ``world/estimates/<branch>/position`` and ``.../heading``: ``Points2D`` and ``Arrows2D`` at
  every ``ESTIMATE_STRIDE``-th sample;
- ``world/estimates/<branch>/ellipse``: the ``ELLIPSE_SIGMA``-sigma position covariance
  ellipse at the same samples, ``LineStrips2D``; for the fused branch under a clamp rule, the
  box of its last clamp from the first clamp on (class ``fused_box``);
- ``intervals/box_width_m`` (the larger side of the hull of the set), ``intervals/area_m2``,
  ``intervals/epoch_ms``, ``intervals/status`` (the index of ``scenarios.epochs.STATUS``:
  0 global, 1 tracking, 2 inconsistent, 3 lost), ``intervals/q_used`` and
  ``intervals/coarse`` (1 where a budget made the set a coarser cover, else 0: ``max_boxes``,
  or with ``free_space`` false a tracking epoch's tests,
  :data:`intervals.tracker.LOST_ECHO_TRACKING_TESTS`): per-epoch figures, ``Scalars`` (E)
  styled by ``SeriesLines``;
- ``errors/position_m/<branch>``, ``errors/heading_rad/<branch>``: estimation errors,
  ``Scalars`` at the same samples as the estimates, in the branch's colour.

The particle filter instead (``estimator = "mcl"``, ``scenarios.mcl_pipeline``), class ``mcl``:

- ``world/estimates/mcl/path``, ``.../trail``, ``.../position``, ``.../heading`` and
  ``.../ellipse`` (its particle covariance): as a branch's;
- ``world/mcl/particles``: the particle set after each filter update (and the prior at 0),
  at most ``scenarios.mcl_pipeline.PARTICLES_SHOWN`` of them, ``Points2D`` (U rows);
- ``mcl/particles``: the size of the set at each update (KLD-sampling), ``Scalars`` (U);
- ``errors/position_m/mcl``, ``errors/heading_rad/mcl``: as a branch's.
"""

from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pyarrow as pa
import rerun as rr
import rerun.blueprint as rrb

from robotsim.robot import wrap_angle
from scenarios.epochs import STATUS
from scenarios.errors import InternalError
from scenarios.mcl_pipeline import MCL_BRANCH, MclEstimation
from scenarios.outputs import write_bytes
from scenarios.runner import BRANCHES

if TYPE_CHECKING:
    from robotsim.obstacles import Obstacles
    from robotsim.sensors.sonar import SonarBeltParams
    from robotsim.simulation import SimulationLog
    from scenarios.epochs import EpochLog
    from scenarios.runner import Estimation

    AnyEstimation = Estimation | MclEstimation
    from scenarios.spec import ScenarioSpec

APPLICATION_ID = "robotsim"
TIMELINE = "time"

#: The map view's root: rerun's 2-D y-down frame; ``world`` below it is the map frame, y up.
VIEW_ROOT = "/"
WORLD = "world"
#: The notes (the legend explained), a markdown ``TextDocument``.
NOTES = "notes/legend"
#: ``world`` -> ``VIEW_ROOT``: ``(x, y) -> (x, -y)``, so that y points up on the screen.
Y_UP = ((1.0, 0.0, 0.0), (0.0, -1.0, 0.0), (0.0, 0.0, 1.0))


@dataclasses.dataclass(frozen=True)
class DrawClass:
    """One kind of thing drawn: its class id in the annotation context, short legend label,
    RGBA colour, the colour's name and what it shows (for the notes tab)."""

    id: int
    label: str
    color: tuple[int, int, int, int]
    color_name: str
    meaning: str


#: Every kind of thing drawn in the map, by name (the legend lists them in this order).
CLASSES = {
    "truth": DrawClass(
        1, "truth", (60, 210, 90, 255), "green", "the true pose: footprint disk, heading, trail"
    ),
    "ukf_only": DrawClass(
        2,
        "UKF only",
        (90, 150, 255, 255),
        "blue",
        "dead reckoning alone (UKF on encoders, gyro, accelerometer), its 2-sigma ellipse",
    ),
    "fused": DrawClass(
        3,
        "fused",
        (255, 150, 20, 255),
        "orange",
        "the same UKF fused with the interval boxes at every epoch",
    ),
    "fused_box": DrawClass(
        4,
        "fused: clamp box",
        (255, 205, 120, 255),
        "light orange",
        "under the clamp rules, the box the fused estimate was last clamped to (the hull of "
        "the component used), drawn instead of its covariance: the clamp moves the mean only, "
        "so the covariance the fused branch carries is the UKF-only one and says nothing of "
        "its error; the truncated rules do update the covariance, and their fused ellipse is it",
    ),
    "mcl": DrawClass(
        5, "MCL", (200, 100, 230, 255), "purple", "Monte Carlo localisation, when the run has it"
    ),
    "outer_box": DrawClass(
        6,
        "outer boxes",
        (230, 70, 70, 255),
        "red",
        "the interval set: boxes that may hold the pose; the truth is in one of them unless "
        "more than q readings of the scan are outliers",
    ),
    "inner_box": DrawClass(
        7,
        "inner boxes",
        (255, 180, 180, 255),
        "pink",
        "boxes of the set proved to hold only consistent poses",
    ),
    "hull": DrawClass(
        8,
        "component hull",
        (255, 90, 90, 255),
        "bright red",
        "the hull of each connected component of the set (one per component)",
    ),
    "cone_echo": DrawClass(
        9,
        "cone: echo",
        (120, 170, 220, 150),
        "pale blue",
        "a sonar cone out to its reading",
    ),
    "cone_no_echo": DrawClass(
        10,
        "cone: no echo",
        (150, 150, 150, 45),
        "faint grey",
        "a sonar cone without an echo, drawn out to d_max",
    ),
    "echo": DrawClass(
        11, "echo", (250, 230, 80, 255), "yellow", "the reading on the sensor's axis"
    ),
    "wall": DrawClass(12, "wall", (215, 215, 215, 255), "light grey", "the map's segments"),
    "obstacle": DrawClass(
        13,
        "unmapped obstacle",
        (205, 125, 60, 255),
        "brown",
        "what the world holds that the estimator's map lacks (`[world] obstacles`): the "
        "physics and the sonar see it, the estimator does not",
    ),
}
#: The branches' classes, in :data:`scenarios.runner.BRANCHES` order.
BRANCH_CLASSES = {branch: CLASSES[branch] for branch in BRANCHES}
#: Alpha of the whole-path layer (faint).
FAINT_ALPHA = 70

#: Line widths and point sizes, ui points (screen units, independent of the zoom).
WALL_WIDTH = 1.5
TRAIL_WIDTH = 1.25
PATH_WIDTH = 0.75
ARROW_WIDTH = 2.0
FOOTPRINT_WIDTH = 1.5
ELLIPSE_WIDTH = 1.0
BOX_WIDTH = 0.5
HULL_WIDTH = 1.5
CONE_WIDTH = 0.5
POSITION_SIZE = 3.5
ECHO_SIZE = 2.0
LEGEND_SIZE = 5.0

#: Draw order in the map, back to front.
DRAW_ORDER = {
    "cones": 1.0,
    "boxes": 2.0,
    "hull": 3.0,
    "walls": 4.0,
    "paths": 5.0,
    "ellipses": 6.0,
    "echoes": 7.0,
    "trails": 8.0,
    "estimates": 9.0,
    "truth": 10.0,
    "legend": 11.0,
}

#: Points on the arc of each drawn sonar cone.
CONE_ARC_POINTS = 7
#: Length of the heading arrows, metres.
HEADING_ARROW_M = 0.5
#: The estimates (and the trails) are drawn at every this many samples (10 Hz at 100 Hz).
ESTIMATE_STRIDE = 10
TRAIL_STRIDE = ESTIMATE_STRIDE
#: Points on each covariance ellipse, and its size in standard deviations.
ELLIPSE_POINTS = 25
ELLIPSE_SIGMA = 2.0
#: Margin round the map in the view, metres; height of one legend row, metres.
MAP_MARGIN_M = 0.5
LEGEND_ROW_M = 0.45
#: Columns of the legend under the map.
LEGEND_COLUMNS = 4
#: The epoch-time plot's axis reaches this many times the 95th percentile of the epoch times.
EPOCH_AXIS_FACTOR = 2.0
#: The status plot's fixed axis: q from -1 (no set), the status up to 3 (lost).
STATUS_AXIS = (-1.5, len(STATUS) - 0.5)
#: How the viewer opens: "following" puts the cursor at the end of the recording (the whole
#: trails, the last set) without playing; live, it follows the data as it arrives.
PLAY_STATE = rrb.components.PlayState.Following
#: The trails show this many seconds before the cursor.
TRAIL_WINDOW_S = 60.0
#: The raw-sensor plots show this many seconds before the cursor.
RAW_WINDOW_S = 30.0


#: Width of the plotted series, ui points; the fused errors' is wider, so that it shows round
#: the UKF-only line drawn over it where the two coincide.
SERIES_WIDTH = 1.5
FUSED_SERIES_WIDTH = 3.5


@dataclasses.dataclass(frozen=True)
class SeriesStyle:
    """How one time series is drawn: legend name, colour, width (ui points), interpolation."""

    name: str
    color: tuple[int, int, int, int]
    width: float = SERIES_WIDTH
    interpolation: rr.components.InterpolationMode = rr.components.InterpolationMode.Linear


#: The styles of the per-epoch series; the branches' error series take their class colours.
EPOCH_SERIES = {
    "intervals/box_width_m": SeriesStyle("hull width (larger side)", CLASSES["hull"].color),
    "intervals/area_m2": SeriesStyle("area of the outer boxes", CLASSES["outer_box"].color),
    "intervals/epoch_ms": SeriesStyle("time per epoch (wall clock)", (200, 200, 200, 255)),
    "intervals/status": SeriesStyle(
        "status: " + ", ".join(f"{i} {name}" for i, name in enumerate(STATUS)),
        (230, 230, 230, 255),
        interpolation=rr.components.InterpolationMode.StepAfter,
    ),
    "intervals/q_used": SeriesStyle(
        "q: outliers GOMNE allowed (-1: no set)",
        (250, 230, 80, 255),
        interpolation=rr.components.InterpolationMode.StepAfter,
    ),
    "intervals/coarse": SeriesStyle(
        "coarse: 1 where a budget (max_boxes, or lost echoes' tracking tests) coarsened the set",
        (240, 120, 60, 255),
        interpolation=rr.components.InterpolationMode.StepAfter,
    ),
}


def write_recording(
    path: str | Path,
    spec: ScenarioSpec,
    log: SimulationLog,
    estimation: AnyEstimation | None = None,
) -> None:
    """Write the recording of ``log`` (a run of ``spec``) and of its ``estimation`` (if any)
    to the ``.rrd`` file ``path``, then read it back (:func:`verify_recording`).

    rerun encodes into memory (a binary stream) and this function writes the bytes: rerun's
    own file sink only logs a failed write (a full disk) and then blocks on disconnect, so a
    truncated file could not be told from a complete one. Here a failed write raises an
    ``OSError`` naming ``path``.
    """
    write_bytes(path, recording_bytes(spec, log, estimation))
    verify_recording(path, recording_id(spec))


def recording_id(spec: ScenarioSpec) -> str:
    """The recording's id: the scenario's name and seed."""
    return f"{spec.name}-seed{spec.run.seed}"


def recording_bytes(
    spec: ScenarioSpec, log: SimulationLog, estimation: AnyEstimation | None = None
) -> bytes:
    """The ``.rrd`` bytes of the recording :func:`write_recording` writes (encoded in
    memory; a campaign's worker sends them to the process that writes its folder)."""
    rec = rr.RecordingStream(APPLICATION_ID, recording_id=recording_id(spec))
    stream = rr.binary_stream(rec)
    rec.send_blueprint(
        default_blueprint(spec.map.bounds, epoch_axis(estimation), estimate_names(estimation)),
        make_active=False,
        make_default=True,
    )
    record_all(rec, spec, log, estimation)
    rec.flush()
    rec.disconnect()
    data = stream.read()
    return b"" if data is None else data


def verify_recording(path: str | Path, recording_id: str) -> None:
    """Read the ``.rrd`` file ``path`` back with rerun's reader: it must end with its footer
    (the manifest rerun writes last) and hold the recording ``recording_id``.

    Raises:
        InternalError: the file is truncated, unreadable or holds another recording.
    """
    from rerun.chunk import RrdReader

    try:
        with warnings.catch_warnings():  # a file without footer also warns: the error says it
            warnings.simplefilter("ignore")
            reader = RrdReader(path)
            found = [entry.recording_id for entry in reader.recordings()]
            reader.store()  # reads the footer's manifest: fails on a truncated file
    except (RuntimeError, ValueError, OSError) as exc:
        raise InternalError(f"the recording {path} does not read back: {exc}") from exc
    if found != [recording_id]:
        raise InternalError(f"the recording {path} holds {found}, not [{recording_id!r}]")


def stream_recording(
    spec: ScenarioSpec,
    log: SimulationLog,
    estimation: AnyEstimation | None = None,
    *,
    spawn: bool = False,
    connect_url: str | None = None,
) -> None:
    """Send the same recording, with the same blueprint, to a live viewer: a new one
    (``spawn``: rerun's viewer started and connected to) or a running one at ``connect_url``
    (a ``rerun+http://host:port/proxy`` URL, see :func:`viewer_url`)."""
    rec = rr.RecordingStream(APPLICATION_ID, recording_id=recording_id(spec))
    blueprint = default_blueprint(
        spec.map.bounds, epoch_axis(estimation), estimate_names(estimation)
    )
    if spawn:
        rec.spawn(default_blueprint=blueprint)
    else:
        rec.connect_grpc(connect_url, default_blueprint=blueprint)
    record_all(rec, spec, log, estimation)
    rec.flush()
    rec.disconnect()


def viewer_url(address: str | None) -> str | None:
    """The gRPC URL of a viewer given as ``host:port`` or as a full URL (``None``: rerun's
    default, ``rerun+http://127.0.0.1:9876/proxy``)."""
    if not address or "://" in address:
        return address or None
    return f"rerun+http://{address}/proxy"


def record_all(
    rec: rr.RecordingStream,
    spec: ScenarioSpec,
    log: SimulationLog,
    estimation: AnyEstimation | None = None,
) -> None:
    """Everything the recording holds, sent to ``rec``: the frame and the classes, the run,
    and the estimation (if any: the interval pipeline's or the particle filter's)."""
    if isinstance(estimation, MclEstimation):
        record_frame(rec, spec.map.bounds, None, mcl=True, obstacles=bool(spec.obstacles))
        record_run(rec, spec, log)
        record_mcl(rec, log, estimation)
        return
    fusion_rule = spec.estimation.fusion if estimation is not None else None
    record_frame(rec, spec.map.bounds, fusion_rule, obstacles=bool(spec.obstacles))
    record_run(rec, spec, log)
    if estimation is not None:
        record_estimation(rec, spec, log, estimation)


def map_view_bounds(bounds: np.ndarray) -> tuple[tuple[float, float], tuple[float, float]]:
    """The map view's fixed ``x_range, y_range`` in the view's (y-down) frame: the map
    ``bounds [[xmin, xmax], [ymin, ymax]]`` metres with a margin, and the legend under it."""
    (x0, x1), (y0, y1) = np.asarray(bounds, dtype=float)
    longest = legend_classes("clamp", obstacles=True)
    legend_rows = -(-len(longest) // LEGEND_COLUMNS)
    bottom = y0 - MAP_MARGIN_M - (legend_rows + 1) * LEGEND_ROW_M
    return (x0 - MAP_MARGIN_M, x1 + MAP_MARGIN_M), (-(y1 + MAP_MARGIN_M), -bottom)


def estimate_names(estimation: AnyEstimation | None) -> tuple[str, ...]:
    """The estimates a recording of ``estimation`` draws: the particle filter's, or the
    interval pipeline's branches (also drawn for no estimation: their overrides are harmless)."""
    return (MCL_BRANCH,) if isinstance(estimation, MclEstimation) else BRANCHES


def epoch_axis(estimation: AnyEstimation | None) -> tuple[float, float] | None:
    """The epoch-time plot's axis, ms: up to ``EPOCH_AXIS_FACTOR`` times the 95th percentile
    of the epoch times, so that a few slow epochs (the global localisation) do not flatten
    the others; ``None`` (the viewer's own) without epochs or when nothing would be clipped."""
    if (
        estimation is None
        or isinstance(estimation, MclEstimation)
        or len(estimation.epochs.elapsed_s) == 0
    ):
        return None
    epoch_ms = estimation.epochs.elapsed_s * 1e3
    top = EPOCH_AXIS_FACTOR * float(np.percentile(epoch_ms, 95))
    return (0.0, top) if epoch_ms.max() > top > 0 else None


def default_blueprint(
    bounds: np.ndarray,
    epoch_ms_range: tuple[float, float] | None = None,
    estimates: tuple[str, ...] = BRANCHES,
) -> rrb.Blueprint:
    """The map (y up, fixed to the map ``bounds (2, 2)``) beside tabs of plots: the
    localisation figures grouped by unit (the epoch time on ``epoch_ms_range``, see
    :func:`epoch_axis`), the raw sensors, and the notes; ``estimates``: the estimates drawn
    (:func:`estimate_names`), whose trails and paths the map view styles."""
    x_range, y_range = map_view_bounds(bounds)
    cursor = rrb.TimeRangeBoundary.cursor_relative(seconds=0.0)
    trail_window = rrb.VisibleTimeRanges(
        timeline=TIMELINE,
        start=rrb.TimeRangeBoundary.cursor_relative(seconds=-TRAIL_WINDOW_S),
        end=cursor,
    )
    trails = [f"{WORLD}/robot/trail"] + [f"{WORLD}/estimates/{b}/trail" for b in estimates]
    paths = [f"{WORLD}/robot/path"] + [f"{WORLD}/estimates/{b}/path" for b in estimates]
    overrides: dict = dict.fromkeys(trails, trail_window)
    overrides.update({path: rrb.EntityBehavior(visible=False) for path in paths})
    map_view = rrb.Spatial2DView(
        origin=VIEW_ROOT,
        contents=[f"/{WORLD}/**"],
        name="map (y up; whole paths hidden, tick */path to show)",
        visual_bounds=rrb.VisualBounds2D(x_range=x_range, y_range=y_range),
        overrides=overrides,
        # the class labels only in the legend (which sets show_labels), not on every instance
        defaults=[
            archetype.from_fields(show_labels=False)
            for archetype in (rr.Points2D, rr.LineStrips2D, rr.Boxes2D, rr.Ellipses2D, rr.Arrows2D)
        ],
    )
    # the localisation plots show the whole run; the raw sensors a window before the cursor
    whole_run = rrb.TimeAxis(
        link="Independent",
        view_range=rrb.TimeRange(
            start=rrb.TimeRangeBoundary.infinite(), end=rrb.TimeRangeBoundary.infinite()
        ),
    )
    raw_start = rrb.TimeRangeBoundary.cursor_relative(seconds=-RAW_WINDOW_S)
    raw_window = rrb.VisibleTimeRanges(timeline=TIMELINE, start=raw_start, end=cursor)
    raw_axis = rrb.TimeAxis(link="Independent", view_range=rrb.TimeRange(raw_start, cursor))

    def plot(
        name: str,
        *contents: str,
        raw: bool = False,
        y_range: tuple[float, float] | None = None,
    ) -> rrb.TimeSeriesView:
        return rrb.TimeSeriesView(
            origin="/",
            contents=list(contents),
            name=name,
            plot_legend=rrb.PlotLegend(corner="LeftTop"),
            time_ranges=raw_window if raw else None,
            axis_x=raw_axis if raw else whole_run,
            axis_y=rrb.ScalarAxis(range=y_range) if y_range else None,
        )

    localisation = rrb.Vertical(
        plot("position error (m)", "/errors/position_m/**"),
        plot("heading error (rad)", "/errors/heading_rad/**"),
        plot("interval set width (m)", "/intervals/box_width_m"),
        plot("interval set area (m²)", "/intervals/area_m2"),
        plot(
            "interval epoch time (ms)"
            if epoch_ms_range is None
            else "interval epoch time (ms; slower epochs off the scale)",
            "/intervals/epoch_ms",
            y_range=epoch_ms_range,
        ),
        plot(
            "epoch status, outliers q and coarse (steps)",
            "/intervals/status",
            "/intervals/q_used",
            "/intervals/coarse",
            y_range=STATUS_AXIS,
        ),
        name="localisation",
    )
    raw = rrb.Vertical(
        plot("encoders (ticks per sample)", "/sensors/encoders/**", raw=True),
        plot("gyro (rad/s)", "/sensors/gyro/**", raw=True),
        plot("accelerometer (m/s²)", "/sensors/accelerometer/**", raw=True),
        plot("true speed (m/s)", "/truth/v_m_s", raw=True),
        plot("true turn rate (rad/s)", "/truth/omega_rad_s", raw=True),
        name="raw sensors",
    )
    return rrb.Blueprint(
        rrb.Horizontal(
            map_view,
            rrb.Tabs(
                localisation,
                raw,
                rrb.TextDocumentView(origin=NOTES, name="legend"),
                active_tab=0,
            ),
            column_shares=[3, 2],
        ),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(timeline=TIMELINE, play_state=PLAY_STATE, state="expanded"),
    )


def legend_classes(
    fusion_rule: str | None, mcl: bool = False, obstacles: bool = False
) -> list[DrawClass]:
    """The classes the legend lists: everything drawn in a run with the estimation's
    ``fusion_rule`` (``None``: no interval pipeline); the MCL and unmapped-obstacle slots only
    when they are drawn."""
    drawn = ["truth", "wall", "cone_echo", "cone_no_echo", "echo"]
    if mcl:
        drawn.append("mcl")
    if obstacles:
        drawn.append("obstacle")
    if fusion_rule is not None:
        drawn += ["ukf_only", "fused", "outer_box", "inner_box", "hull"]
        drawn.append(fused_outline_class(fusion_rule))
    return [CLASSES[name] for name in CLASSES if name in drawn]


def record_frame(
    rec: rr.RecordingStream,
    bounds: np.ndarray,
    fusion_rule: str | None,
    mcl: bool = False,
    obstacles: bool = False,
) -> None:
    """The y-up transform and the annotation context on ``world``, the legend under the map
    ``bounds (2, 2)`` (:data:`LEGEND_COLUMNS` columns of labelled points) and the notes that
    explain it, static (``mcl``: the particle filter's run; ``obstacles``: the world has
    unmapped obstacles)."""
    # one row (one call): the batcher may split or merge separate calls by wall-clock timing
    rec.log(
        WORLD,
        rr.Transform3D(mat3x3=Y_UP),
        rr.AnnotationContext(
            [rr.AnnotationInfo(id=c.id, label=c.label, color=c.color) for c in CLASSES.values()]
        ),
        static=True,
    )
    shown = legend_classes(fusion_rule, mcl, obstacles)
    (x0, x1), (y0, _) = np.asarray(bounds, dtype=float)
    column, row = np.divmod(np.arange(len(shown)), LEGEND_COLUMNS)[::-1]
    positions = np.stack(
        [
            x0 + (column + 0.5) * (x1 - x0) / LEGEND_COLUMNS,
            y0 - MAP_MARGIN_M - (row + 1) * LEGEND_ROW_M,
        ],
        axis=1,
    )
    rec.log(
        f"{WORLD}/legend",
        rr.Points2D(
            positions,
            class_ids=[c.id for c in shown],
            colors=[(*c.color[:3], 255) for c in shown],  # opaque, so that faint classes read
            labels=[c.label for c in shown],
            show_labels=True,
            radii=rr.Radius.ui_points(LEGEND_SIZE),
            draw_order=DRAW_ORDER["legend"],
        ),
        static=True,
    )
    rec.log(NOTES, rr.TextDocument(legend_notes(shown), media_type="text/markdown"), static=True)


def legend_notes(shown: list[DrawClass]) -> str:
    """The notes tab: what each colour in the map shows, and how to read the view."""
    lines = [
        "# How to read this recording",
        "",
        "The map is drawn **y up** (as the project's figures), in metres. The truth and both "
        f"estimates draw a trail of the last {TRAIL_WINDOW_S:g} s up to the time cursor; their "
        "whole paths are a faint layer, hidden by default (show `*/path` in the blueprint "
        "panel).",
        "",
        *(f"- **{c.label}** ({c.color_name}): {c.meaning}." for c in shown),
        "",
        "The plots are grouped by unit; the raw sensors show the last "
        f"{RAW_WINDOW_S:g} s before the cursor. Epoch status: "
        + ", ".join(f"{i} {name}" for i, name in enumerate(STATUS))
        + ".",
    ]
    return "\n".join(lines)


def record_run(rec: rr.RecordingStream, spec: ScenarioSpec, log: SimulationLog) -> None:
    """Send the map, the truth, the sonar scans and the sensor series of one run to ``rec``."""
    record_map(rec, spec.map.segments)
    record_obstacles(rec, spec.obstacles, log.t_s[::ESTIMATE_STRIDE])
    record_truth(rec, log.t_s, log.pose, log.velocity, spec.robot.radius_m)
    record_sonar(rec, log.sonar_t_s, log.sonar_pose, log.sonar_range_m, spec.sensors.sonar)
    record_proprioceptive(rec, log.t_s, log.wheel_ticks, log.gyro_rad_s, log.accel_m_s2)


def record_map(rec: rr.RecordingStream, segments: np.ndarray) -> None:
    """The map walls ``(m, 2, 2)``, static."""
    rec.log(
        f"{WORLD}/map/walls",
        rr.LineStrips2D(
            segments,
            class_ids=CLASSES["wall"].id,
            radii=rr.Radius.ui_points(WALL_WIDTH),
            draw_order=DRAW_ORDER["walls"],
        ),
        static=True,
    )


def record_obstacles(rec: rr.RecordingStream, obstacles: Obstacles, t_s: np.ndarray) -> None:
    """The unmapped obstacles: the edges of those that stand still, static, and those of the
    moving ones at the times ``t_s (n,)``, s (nothing when the world has none)."""
    if len(obstacles.static_edges_m):
        rec.log(
            f"{WORLD}/obstacles/static",
            rr.LineStrips2D(
                obstacles.static_edges_m,
                class_ids=CLASSES["obstacle"].id,
                radii=rr.Radius.ui_points(WALL_WIDTH),
                draw_order=DRAW_ORDER["walls"],
            ),
            static=True,
        )
    if not obstacles.moving or not len(t_s):
        return
    edges = obstacles.moving_edges_m(t_s)  # (n, e, 2, 2)
    n, e = edges.shape[:2]
    rec.send_columns(
        f"{WORLD}/obstacles/moving",
        indexes=[rr.TimeColumn(TIMELINE, duration=t_s)],
        columns=rr.LineStrips2D.columns(
            strips=edges.reshape(n * e, 2, 2),
            class_ids=np.full(n * e, CLASSES["obstacle"].id, dtype=np.uint16),
            radii=np.full(n * e, rr.Radius.ui_points(WALL_WIDTH), dtype=np.float32),
            draw_order=np.full(n * e, DRAW_ORDER["walls"], dtype=np.float32),
        ).partition(np.full(n, e)),
    )


def faint(color: tuple[int, int, int, int]) -> tuple[int, int, int, int]:
    """``color`` with the whole-path layer's alpha."""
    return (*color[:3], FAINT_ALPHA)


def record_path(
    rec: rr.RecordingStream, base: str, t_s: np.ndarray, xy: np.ndarray, style: DrawClass
) -> None:
    """The whole path ``xy (N, 2)`` (static, faint) under ``base/path``, and its trail under
    ``base/trail``: the segment from the previous ``TRAIL_STRIDE``-th sample to each one,
    at its time (the blueprint shows the last ``TRAIL_WINDOW_S`` seconds of them)."""
    rec.log(
        f"{base}/path",
        rr.LineStrips2D(
            [np.ascontiguousarray(xy)],
            class_ids=style.id,
            colors=faint(style.color),
            radii=rr.Radius.ui_points(PATH_WIDTH),
            draw_order=DRAW_ORDER["paths"],
        ),
        static=True,
    )
    shown = np.ascontiguousarray(xy[::TRAIL_STRIDE])
    segments = np.stack([np.concatenate([shown[:1], shown[:-1]]), shown], axis=1)  # (S, 2, 2)
    rec.send_columns(
        f"{base}/trail",
        indexes=[rr.TimeColumn(TIMELINE, duration=t_s[::TRAIL_STRIDE])],
        columns=rr.LineStrips2D.columns(strips=segments),
    )
    rec.log(
        f"{base}/trail",
        rr.LineStrips2D.from_fields(
            class_ids=style.id,
            radii=rr.Radius.ui_points(TRAIL_WIDTH),
            draw_order=DRAW_ORDER["trails"],
        ),
        static=True,
    )


def heading_vectors(theta_rad: np.ndarray) -> np.ndarray:
    """Arrows ``(N, 2)`` of length ``HEADING_ARROW_M`` along the headings ``theta_rad (N,)``."""
    return HEADING_ARROW_M * np.stack([np.cos(theta_rad), np.sin(theta_rad)], axis=1)


def record_truth(
    rec: rr.RecordingStream,
    t_s: np.ndarray,
    pose: np.ndarray,
    velocity: np.ndarray,
    radius_m: float,
) -> None:
    """The true path and trail, footprint and heading ``pose (N, 3)``, and velocity ``(N, 2)``.

    The footprint and the arrow carry their style in every row (one row per sample)."""
    times = [rr.TimeColumn(TIMELINE, duration=t_s)]
    xy = np.ascontiguousarray(pose[:, :2])
    n = len(t_s)
    truth = CLASSES["truth"]
    record_path(rec, f"{WORLD}/robot", t_s, xy, truth)
    class_ids = np.full(n, truth.id, dtype=np.uint16)
    draw_order = np.full(n, DRAW_ORDER["truth"], dtype=np.float32)
    rec.send_columns(
        f"{WORLD}/robot/footprint",
        indexes=times,
        columns=rr.Ellipses2D.columns(
            centers=xy,
            half_sizes=np.full((n, 2), radius_m),
            class_ids=class_ids,
            line_radii=np.full(n, rr.Radius.ui_points(FOOTPRINT_WIDTH), dtype=np.float32),
            draw_order=draw_order,
        ),
    )
    rec.send_columns(
        f"{WORLD}/robot/heading",
        indexes=times,
        columns=rr.Arrows2D.columns(
            origins=xy,
            vectors=heading_vectors(pose[:, 2]),
            class_ids=class_ids,
            radii=np.full(n, rr.Radius.ui_points(ARROW_WIDTH), dtype=np.float32),
            draw_order=draw_order,
        ),
    )
    rec.send_columns(
        "truth/v_m_s", indexes=times, columns=rr.Scalars.columns(scalars=velocity[:, 0])
    )
    rec.send_columns(
        "truth/omega_rad_s", indexes=times, columns=rr.Scalars.columns(scalars=velocity[:, 1])
    )


def sensor_positions(
    sonar_pose: np.ndarray, mount_xy_m: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """World positions ``x, y`` ``(M, k)`` of the sensors: ``s_i = (x, y) + R(theta) s~_i``."""
    x, y, theta = sonar_pose[:, 0, None], sonar_pose[:, 1, None], sonar_pose[:, 2, None]
    cos_t, sin_t = np.cos(theta), np.sin(theta)
    return (
        x + cos_t * mount_xy_m[:, 0] - sin_t * mount_xy_m[:, 1],
        y + sin_t * mount_xy_m[:, 0] + cos_t * mount_xy_m[:, 1],
    )


def cone_outlines(
    sonar_pose: np.ndarray,
    range_m: np.ndarray,
    mount_xy_m: np.ndarray,
    mount_angle_rad: np.ndarray,
    half_aperture_rad: float,
    d_max_m: float,
) -> np.ndarray:
    """Closed outlines ``(M, k, CONE_ARC_POINTS + 2, 2)`` of every cone at every scan.

    Each outline goes from the sensor, out along one edge to the reading (``d_max_m`` when
    there is no echo), round the arc, and back to the sensor.
    """
    sx, sy = sensor_positions(sonar_pose, mount_xy_m)
    theta = sonar_pose[:, 2, None]
    reach = np.where(np.isfinite(range_m), range_m, d_max_m)  # (M, k)
    arc = np.linspace(-half_aperture_rad, half_aperture_rad, CONE_ARC_POINTS)
    phi = (theta + mount_angle_rad)[..., None] + arc  # (M, k, A)
    arc_x = sx[..., None] + reach[..., None] * np.cos(phi)
    arc_y = sy[..., None] + reach[..., None] * np.sin(phi)
    outline = np.empty((*range_m.shape, CONE_ARC_POINTS + 2, 2))
    outline[..., 0, 0], outline[..., 0, 1] = sx, sy
    outline[..., 1:-1, 0], outline[..., 1:-1, 1] = arc_x, arc_y
    outline[..., -1, :] = outline[..., 0, :]
    return outline


def echo_points(
    sonar_pose: np.ndarray, range_m: np.ndarray, mount_xy_m: np.ndarray, mount_angle_rad: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """World points ``(E, 2)`` of the finite readings on their sensors' axes, and counts ``(M,)``."""
    sx, sy = sensor_positions(sonar_pose, mount_xy_m)
    theta = sonar_pose[:, 2, None]
    echo = np.isfinite(range_m)
    reach = np.where(echo, range_m, 0.0)
    phi = theta + mount_angle_rad
    points = np.stack([sx + reach * np.cos(phi), sy + reach * np.sin(phi)], axis=-1)
    return points[echo], echo.sum(axis=1)


def record_sonar(
    rec: rr.RecordingStream,
    sonar_t_s: np.ndarray,
    sonar_pose: np.ndarray,
    range_m: np.ndarray,
    belt: SonarBeltParams,
) -> None:
    """The cones ``(M scans x k sensors)`` and the echo points of every scan of ``belt``; a
    cone without an echo (drawn to ``d_max``) is in the fainter ``cone_no_echo`` class."""
    scans, sensors = range_m.shape
    if scans == 0:
        return
    times = [rr.TimeColumn(TIMELINE, duration=sonar_t_s)]
    outlines = cone_outlines(
        sonar_pose,
        range_m,
        belt.mount_xy,
        belt.mount_angle_rad,
        belt.half_aperture_rad,
        belt.d_max_m,
    )
    class_ids = np.where(
        np.isfinite(range_m), CLASSES["cone_echo"].id, CLASSES["cone_no_echo"].id
    ).astype(np.uint16)
    strips = scans * sensors
    rec.send_columns(
        f"{WORLD}/sonar/cones",
        indexes=times,
        columns=rr.LineStrips2D.columns(
            strips=outlines.reshape(strips, -1, 2),
            class_ids=class_ids.reshape(-1),
            radii=np.full(strips, rr.Radius.ui_points(CONE_WIDTH), dtype=np.float32),
            draw_order=np.full(strips, DRAW_ORDER["cones"], dtype=np.float32),
        ).partition(np.full(scans, sensors)),
    )
    points, counts = echo_points(sonar_pose, range_m, belt.mount_xy, belt.mount_angle_rad)
    rec.send_columns(
        f"{WORLD}/sonar/echoes",
        indexes=times,
        columns=rr.Points2D.columns(
            positions=points,
            class_ids=np.full(len(points), CLASSES["echo"].id, dtype=np.uint16),
            radii=np.full(len(points), rr.Radius.ui_points(ECHO_SIZE), dtype=np.float32),
            draw_order=np.full(len(points), DRAW_ORDER["echoes"], dtype=np.float32),
        ).partition(counts),
    )


def record_proprioceptive(
    rec: rr.RecordingStream,
    t_s: np.ndarray,
    wheel_ticks: np.ndarray,
    gyro_rad_s: np.ndarray,
    accel_m_s2: np.ndarray,
) -> None:
    """Encoder ticks ``(N, 2)``, gyro rate ``(N,)`` and specific force ``(N, 2)`` series."""
    times = [rr.TimeColumn(TIMELINE, duration=t_s)]
    series = {
        "sensors/encoders/left": wheel_ticks[:, 0],
        "sensors/encoders/right": wheel_ticks[:, 1],
        "sensors/gyro/rate_rad_s": gyro_rad_s,
        "sensors/accelerometer/x_m_s2": accel_m_s2[:, 0],
        "sensors/accelerometer/y_m_s2": accel_m_s2[:, 1],
    }
    for entity, values in series.items():
        rec.send_columns(
            entity,
            indexes=times,
            columns=rr.Scalars.columns(scalars=np.asarray(values, dtype=np.float64)),
        )


def send_series(
    rec: rr.RecordingStream, entity: str, t_s: np.ndarray, values: np.ndarray, style: SeriesStyle
) -> None:
    """One scalar series ``values (n,)`` at ``t_s (n,)`` with its ``SeriesLines`` style in
    every row (no extra static row)."""
    n = len(t_s)
    rec.send_columns(
        entity,
        indexes=[rr.TimeColumn(TIMELINE, duration=t_s)],
        columns=[
            *rr.Scalars.columns(scalars=np.asarray(values, dtype=np.float64)),
            *rr.SeriesLines.columns(
                colors=np.tile(np.asarray(style.color, dtype=np.uint8), (n, 1)),
                widths=np.full(n, style.width, dtype=np.float32),
                names=[style.name] * n,
                # the uint8 Arrow column rerun would build value by value from n enums
                interpolation_mode=pa.array(np.full(n, style.interpolation.value, dtype=np.uint8)),
            ),
        ],
    )


def fused_outline_class(rule: str) -> str:
    """The class of the fused branch's outline once it has been clamped: the clamp box
    under the clamp rules (they leave the covariance as it was), the ellipse otherwise."""
    return "fused_box" if rule.startswith("clamp") else "fused"


def record_estimation(
    rec: rr.RecordingStream, spec: ScenarioSpec, log: SimulationLog, estimation: Estimation
) -> None:
    """The interval sets, both branches' trails, estimates, headings and outlines, and the
    error and per-epoch series of one run."""
    record_interval_sets(rec, estimation.epochs)
    every = slice(None, None, ESTIMATE_STRIDE)
    t_shown = log.t_s[every]
    truth = log.pose[every]
    n = len(t_shown)
    for b, branch in enumerate(BRANCHES):
        pose, cov = estimation.pose[b], estimation.pose_cov[b]
        style = BRANCH_CLASSES[branch]
        base = f"{WORLD}/estimates/{branch}"
        shown = record_estimate_marks(rec, base, log.t_s, pose, style)
        outlines = covariance_ellipses(shown[:, :2], cov[every, :2, :2])
        class_ids = np.full(n, style.id, dtype=np.uint16)
        if branch == "fused" and fused_outline_class(spec.estimation.fusion) == "fused_box":
            outlines, class_ids = clamp_box_outlines(
                log.t_s[every], outlines, class_ids, log.t_s[estimation.epoch_index], estimation
            )
        record_outlines(rec, base, t_shown, outlines, class_ids)
        # the fused line (drawn first) wider than the UKF-only one, which may hide it
        width = FUSED_SERIES_WIDTH if branch == "fused" else SERIES_WIDTH
        record_errors(
            rec,
            branch,
            t_shown,
            shown,
            truth,
            SeriesStyle(style.label, style.color, width),
            SeriesStyle(heading_series_name(branch, spec.estimation.fusion), style.color, width),
        )


def record_estimate_marks(
    rec: rr.RecordingStream, base: str, t_s: np.ndarray, pose: np.ndarray, style: DrawClass
) -> np.ndarray:
    """An estimate ``pose (N, 3)`` at the samples ``t_s (N,)``: its path and trail, and its
    position and heading at every ``ESTIMATE_STRIDE``-th sample under ``base``; returns
    those poses ``(S, 3)``."""
    record_path(rec, base, t_s, pose[:, :2], style)
    shown = pose[::ESTIMATE_STRIDE]
    times = [rr.TimeColumn(TIMELINE, duration=t_s[::ESTIMATE_STRIDE])]
    rec.send_columns(
        f"{base}/position", indexes=times, columns=rr.Points2D.columns(positions=shown[:, :2])
    )
    rec.log(
        f"{base}/position",
        rr.Points2D.from_fields(
            class_ids=style.id,
            radii=rr.Radius.ui_points(POSITION_SIZE),
            draw_order=DRAW_ORDER["estimates"],
        ),
        static=True,
    )
    rec.send_columns(
        f"{base}/heading",
        indexes=times,
        columns=rr.Arrows2D.columns(origins=shown[:, :2], vectors=heading_vectors(shown[:, 2])),
    )
    rec.log(
        f"{base}/heading",
        rr.Arrows2D.from_fields(
            class_ids=style.id,
            radii=rr.Radius.ui_points(ARROW_WIDTH),
            draw_order=DRAW_ORDER["estimates"],
        ),
        static=True,
    )
    return shown


def record_outlines(
    rec: rr.RecordingStream,
    base: str,
    t_s: np.ndarray,
    outlines: np.ndarray,
    class_ids: np.ndarray,
) -> None:
    """An estimate's outlines ``(S, P, 2)`` (covariance ellipses or boxes) at ``t_s (S,)``."""
    rec.send_columns(
        f"{base}/ellipse",
        indexes=[rr.TimeColumn(TIMELINE, duration=t_s)],
        columns=rr.LineStrips2D.columns(strips=outlines, class_ids=class_ids),
    )
    rec.log(
        f"{base}/ellipse",
        rr.LineStrips2D.from_fields(
            radii=rr.Radius.ui_points(ELLIPSE_WIDTH), draw_order=DRAW_ORDER["ellipses"]
        ),
        static=True,
    )


def record_errors(
    rec: rr.RecordingStream,
    name: str,
    t_s: np.ndarray,
    shown: np.ndarray,
    truth: np.ndarray,
    position_style: SeriesStyle,
    heading_style: SeriesStyle,
) -> None:
    """The position and heading errors of the poses ``shown (S, 3)`` against ``truth (S, 3)``
    at ``t_s (S,)``, as ``errors/position_m/<name>`` and ``errors/heading_rad/<name>``."""
    error_xy = np.linalg.norm(shown[:, :2] - truth[:, :2], axis=1)
    error_theta = np.abs(wrap_angle(shown[:, 2] - truth[:, 2]))
    send_series(rec, f"errors/position_m/{name}", t_s, error_xy, position_style)
    send_series(rec, f"errors/heading_rad/{name}", t_s, error_theta, heading_style)


#: The particles' point size, ui points (small: there are hundreds).
PARTICLE_SIZE = 1.5


def record_mcl(rec: rr.RecordingStream, log: SimulationLog, estimation: MclEstimation) -> None:
    """The particle filter's estimate (as a branch's: trail, position, heading, covariance
    ellipse, errors), its particles after each update and the set's size."""
    style = CLASSES["mcl"]
    base = f"{WORLD}/estimates/{MCL_BRANCH}"
    shown = record_estimate_marks(rec, base, log.t_s, estimation.pose, style)
    t_shown = log.t_s[::ESTIMATE_STRIDE]
    outlines = covariance_ellipses(shown[:, :2], estimation.pose_cov[::ESTIMATE_STRIDE, :2, :2])
    record_outlines(rec, base, t_shown, outlines, np.full(len(shown), style.id, dtype=np.uint16))
    series = SeriesStyle(style.label, style.color)
    truth = log.pose[::ESTIMATE_STRIDE]
    record_errors(rec, MCL_BRANCH, t_shown, shown, truth, series, series)
    update_t = log.t_s[estimation.update_index]
    rec.send_columns(
        f"{WORLD}/mcl/particles",
        indexes=[rr.TimeColumn(TIMELINE, duration=update_t)],
        columns=rr.Points2D.columns(positions=estimation.particles[:, :2]).partition(
            estimation.shown_count
        ),
    )
    rec.log(
        f"{WORLD}/mcl/particles",
        rr.Points2D.from_fields(
            class_ids=style.id,
            radii=rr.Radius.ui_points(PARTICLE_SIZE),
            draw_order=DRAW_ORDER["ellipses"],
        ),
        static=True,
    )
    send_series(
        rec,
        "mcl/particles",
        update_t,
        estimation.particle_count.astype(np.float64),
        SeriesStyle("particles (KLD-sampling)", style.color),
    )


def heading_series_name(branch: str, rule: str) -> str:
    """The heading-error series' legend name; says so where the fused line is the UKF-only
    one (the position-only clamp never changes the heading)."""
    label = BRANCH_CLASSES[branch].label
    if branch == "fused" and rule == "clamp":
        return f"{label} (= UKF only: the clamp moves the position only)"
    return label


def rectangle_outlines(boxes_xy: np.ndarray, points: int = 5) -> np.ndarray:
    """Closed outlines ``(B, points, 2)`` of the boxes ``(B, 2, 2)`` (``x, y`` rows; lower,
    upper columns): the corners counter-clockwise from the lower left and back to it, each
    corner repeated so that there are ``points >= 5`` (a strip as long as an ellipse's)."""
    corner = np.floor(np.linspace(0.0, 4.0, points)).astype(np.int64)  # 0 0 .. 1 .. 4
    x_side = np.array([0, 1, 1, 0, 0])[corner]
    y_side = np.array([0, 0, 1, 1, 0])[corner]
    return np.stack([boxes_xy[:, 0, x_side], boxes_xy[:, 1, y_side]], axis=-1)


def clamp_box_outlines(
    t_s: np.ndarray,
    ellipses: np.ndarray,
    class_ids: np.ndarray,
    epoch_t_s: np.ndarray,
    estimation: Estimation,
) -> tuple[np.ndarray, np.ndarray]:
    """The fused branch's outlines ``(S, ELLIPSE_POINTS, 2)`` and class ids ``(S,)`` at the
    samples ``t_s (S,)`` under a clamp rule: the box of the last clamp at or before each
    sample (``fused_box`` class) from the first clamp on, the covariance ``ellipses`` before
    it (the fused branch is then the UKF-only one)."""
    clamped = estimation.component >= 0
    clamp_t, boxes = epoch_t_s[clamped], estimation.fused_box[clamped, :2]
    if len(boxes) == 0:
        return ellipses, class_ids
    last = np.searchsorted(clamp_t, t_s, side="right") - 1  # (S,), -1: before the first clamp
    rectangles = rectangle_outlines(boxes, ellipses.shape[1])[np.maximum(last, 0)]
    after = last >= 0
    outlines = np.where(after[:, None, None], rectangles, ellipses)
    return outlines, np.where(after, CLASSES["fused_box"].id, class_ids).astype(np.uint16)


def covariance_ellipses(centres: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """Closed outlines ``(S, ELLIPSE_POINTS, 2)`` of the ``ELLIPSE_SIGMA`` ellipses of the
    position covariances ``cov (S, 2, 2)`` about ``centres (S, 2)``:
    ``c + ELLIPSE_SIGMA * L u`` for ``u`` round the unit circle, ``L L^T = cov``."""
    angle = np.linspace(0.0, 2.0 * np.pi, ELLIPSE_POINTS)
    circle = np.stack([np.cos(angle), np.sin(angle)], axis=-1)  # (A, 2)
    values, vectors = np.linalg.eigh(cov)
    root = vectors * np.sqrt(np.clip(values, 0.0, None))[:, None, :]  # (S, 2, 2), root root^T = cov
    return centres[:, None, :] + ELLIPSE_SIGMA * circle @ root.mT


def component_hulls(epochs: EpochLog) -> tuple[np.ndarray, np.ndarray]:
    """The (x, y) hull of each connected component of each epoch's outer set:
    ``hulls (H, 2, 2)`` (``x, y`` rows; lower, upper) in epoch order, and the number of
    components per epoch ``(E,)`` (0 without a set)."""
    epoch = np.repeat(np.arange(len(epochs.t_s)), epochs.box_counts)  # (B,)
    labels = epochs.labels.astype(np.int64)
    span = int(labels.max()) + 1 if len(labels) else 1
    keys, member = np.unique(epoch * span + labels, return_inverse=True)  # sorted by epoch
    lower = np.full((len(keys), 2), np.inf)
    upper = np.full((len(keys), 2), -np.inf)
    np.minimum.at(lower, member, epochs.boxes[:, :2, 0])
    np.maximum.at(upper, member, epochs.boxes[:, :2, 1])
    counts = np.bincount(keys // span, minlength=len(epochs.t_s))
    return np.stack([lower, upper], axis=-1), counts


def record_interval_sets(rec: rr.RecordingStream, epochs: EpochLog) -> None:
    """The outer boxes and the component hulls of every epoch, and the per-epoch figures as
    time series."""
    if len(epochs.t_s) == 0:
        return
    times = [rr.TimeColumn(TIMELINE, duration=epochs.t_s)]
    boxes = epochs.boxes
    count = len(boxes)
    class_ids = np.where(epochs.inner, CLASSES["inner_box"].id, CLASSES["outer_box"].id)
    rec.send_columns(
        f"{WORLD}/intervals/boxes",
        indexes=times,
        columns=rr.Boxes2D.columns(
            centers=0.5 * (boxes[:, :2, 0] + boxes[:, :2, 1]),
            half_sizes=0.5 * (boxes[:, :2, 1] - boxes[:, :2, 0]),
            class_ids=class_ids.astype(np.uint16),
            radii=np.full(count, rr.Radius.ui_points(BOX_WIDTH), dtype=np.float32),
            draw_order=np.full(count, DRAW_ORDER["boxes"], dtype=np.float32),
        ).partition(epochs.box_counts),
    )
    hulls, components = component_hulls(epochs)
    rec.send_columns(
        f"{WORLD}/intervals/hull",
        indexes=times,
        columns=rr.Boxes2D.columns(
            centers=0.5 * (hulls[:, :, 0] + hulls[:, :, 1]),
            half_sizes=0.5 * (hulls[:, :, 1] - hulls[:, :, 0]),
        ).partition(components),
    )
    rec.log(
        f"{WORLD}/intervals/hull",
        rr.Boxes2D.from_fields(
            class_ids=CLASSES["hull"].id,
            radii=rr.Radius.ui_points(HULL_WIDTH),
            draw_order=DRAW_ORDER["hull"],
        ),
        static=True,
    )
    width = np.max(epochs.hull[:, :2, 1] - epochs.hull[:, :2, 0], axis=1)
    values = {
        "intervals/box_width_m": width,
        "intervals/area_m2": epochs.area_m2,
        "intervals/epoch_ms": epochs.elapsed_s * 1e3,
        "intervals/status": epochs.status.astype(np.float64),
        "intervals/q_used": epochs.q_used.astype(np.float64),
        "intervals/coarse": epochs.coarse.astype(np.float64),
    }
    for entity, series in values.items():
        send_series(rec, entity, epochs.t_s, series, EPOCH_SERIES[entity])
