"""The geometry drawn in the recording: cones and echo points, checked against the readings."""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pytest

from scenarios.recording import CONE_ARC_POINTS, cone_outlines, echo_points

pytestmark = pytest.mark.slow  # real runs written to .rrd files and read back, a live viewer


def belt(k: int = 8, radius_m: float = 0.2):
    angle = np.linspace(-np.pi, np.pi, k, endpoint=False)
    return radius_m * np.stack([np.cos(angle), np.sin(angle)], axis=1), angle


def test_cone_outlines_reach_the_reading_inside_the_aperture():
    rng = np.random.default_rng(3)
    mount_xy, mount_angle = belt()
    poses = np.column_stack(
        [rng.uniform(0, 5, 20), rng.uniform(0, 5, 20), rng.uniform(-np.pi, np.pi, 20)]
    )
    ranges = rng.uniform(0.3, 3.2, (20, 8))
    ranges[rng.random((20, 8)) < 0.3] = np.inf
    gamma, d_max = np.radians(12.5), 3.0
    outline = cone_outlines(poses, ranges, mount_xy, mount_angle, gamma, d_max)
    assert outline.shape == (20, 8, CONE_ARC_POINTS + 2, 2)

    # the apex is the sensor in the world: (x, y) + R(theta) mount
    c, s = np.cos(poses[:, 2, None]), np.sin(poses[:, 2, None])
    apex = np.stack(
        [
            poses[:, 0, None] + c * mount_xy[:, 0] - s * mount_xy[:, 1],
            poses[:, 1, None] + s * mount_xy[:, 0] + c * mount_xy[:, 1],
        ],
        axis=-1,
    )
    np.testing.assert_allclose(outline[:, :, 0], apex)
    np.testing.assert_allclose(outline[:, :, -1], apex)  # closed
    arc = outline[:, :, 1:-1] - apex[:, :, None]
    reach = np.where(np.isfinite(ranges), ranges, d_max)
    np.testing.assert_allclose(
        np.linalg.norm(arc, axis=-1), np.broadcast_to(reach[..., None], arc.shape[:-1])
    )
    axis = poses[:, 2, None] + mount_angle
    offset = np.angle(np.exp(1j * (np.arctan2(arc[..., 1], arc[..., 0]) - axis[..., None])))
    np.testing.assert_allclose(offset[..., 0], -gamma, atol=1e-9)
    np.testing.assert_allclose(offset[..., -1], gamma, atol=1e-9)


def test_echo_points_lie_on_the_axis_at_the_reading():
    mount_xy, mount_angle = belt(4)
    poses = np.array([[1.0, 2.0, 0.3], [4.0, 1.0, -2.0]])
    ranges = np.array([[1.0, np.inf, 2.0, 0.5], [np.inf, np.inf, 3.0, np.inf]])
    points, counts = echo_points(poses, ranges, mount_xy, mount_angle)
    assert counts.tolist() == [3, 1] and points.shape == (4, 2)
    # sensor 0 of pose 0: mount (0.2 at -pi) behind the robot, pointing backwards
    heading = 0.3 + mount_angle[0]
    sensor = np.array([1.0, 2.0]) + 0.2 * np.array([np.cos(heading), np.sin(heading)])
    np.testing.assert_allclose(
        points[0], sensor + 1.0 * np.array([np.cos(heading), np.sin(heading)])
    )
    assert np.isfinite(points).all()


def test_covariance_ellipses_are_the_sigma_contours():
    from scenarios.recording import ELLIPSE_POINTS, ELLIPSE_SIGMA, covariance_ellipses

    rng = np.random.default_rng(1)
    a = rng.normal(size=(6, 2, 2))
    cov = a @ a.mT + 1e-3 * np.eye(2)
    centres = rng.uniform(0, 5, (6, 2))
    outline = covariance_ellipses(centres, cov)
    assert outline.shape == (6, ELLIPSE_POINTS, 2)
    d = outline - centres[:, None, :]
    mahalanobis = np.einsum("spi,sij,spj->sp", d, np.linalg.inv(cov), d)
    np.testing.assert_allclose(mahalanobis, ELLIPSE_SIGMA**2, rtol=1e-9)
    np.testing.assert_allclose(outline[:, 0], outline[:, -1])  # closed


#: Entities whose values are wall-clock measurements (not part of the determinism).
WALL_CLOCK_ENTITIES = ("/intervals/epoch_ms",)


def logged_data(path) -> dict:
    """Every column of a recording read back, per entity path (static or not), without the
    per-run bookkeeping rerun adds (row ids, the recording's start time)."""
    import pyarrow as pa
    from rerun.chunk import RrdReader

    def values(column: pa.Array) -> list:
        if pa.types.is_duration(column.type) or pa.types.is_timestamp(column.type):
            column = column.cast(pa.int64())  # nanoseconds, exactly
        return column.to_pylist()

    data: dict = {}
    for chunk in RrdReader(path).store().stream():
        batch = chunk.to_record_batch()
        columns = {
            name: values(batch.column(name))
            for name in batch.schema.names
            if name != "rerun.controls.RowId" and not name.startswith("RecordingInfo:")
        }
        data.setdefault((chunk.entity_path, chunk.is_static), []).append((batch.num_rows, columns))
    return data


def test_same_scenario_and_seed_log_the_same_data(tmp_path):
    """Determinism covers the logged data: entity paths, row counts and values are equal
    (the .rrd bytes differ: rerun stamps each recording with fresh ids and times), except
    the measured time per interval epoch."""
    from scenarios.recording import write_recording
    from scenarios.runner import run_scenario
    from scenarios.spec import load_scenario

    spec = load_scenario("hall").with_run(duration_s=3.0)
    paths = []
    for name, seed in (("a", 0), ("b", 0), ("c", 1)):
        run_spec = spec.with_run(seed=seed)
        result = run_scenario(run_spec)
        paths.append(tmp_path / f"{name}.rrd")
        write_recording(paths[-1], run_spec, result.log, result.estimation)
    first, second, other_seed = (logged_data(path) for path in paths)
    assert ("/world/robot/footprint", False) in first and len(first) > 20
    assert first.keys() == second.keys()
    for key in first:
        if key[0] not in WALL_CLOCK_ENTITIES:
            assert first[key] == second[key], key
        else:  # same rows and times, measured durations
            assert [(rows, c["time"]) for rows, c in first[key]] == [
                (rows, c["time"]) for rows, c in second[key]
            ]
    assert first != other_seed  # the comparison sees a change of the sensor noise


# --- The recording read back: the frame, the classes, the styles and the blueprint ---------

RUN_S = 4.0


def recorded(tmp_path_factory, rule: str):
    """A short hall run with the fusion ``rule``, its result and its recording's path."""
    import dataclasses

    from scenarios.recording import write_recording
    from scenarios.runner import run_scenario
    from scenarios.spec import load_scenario

    spec = load_scenario("hall").with_run(duration_s=RUN_S)
    spec = dataclasses.replace(spec, estimation=dataclasses.replace(spec.estimation, fusion=rule))
    result = run_scenario(spec)
    path = tmp_path_factory.mktemp(rule) / "hall.rrd"
    write_recording(path, spec, result.log, result.estimation)
    return spec, result, path


@pytest.fixture(scope="module")
def clamp_run(tmp_path_factory):
    return recorded(tmp_path_factory, "clamp")


@pytest.fixture(scope="module")
def truncated_run(tmp_path_factory):
    return recorded(tmp_path_factory, "truncated")


def entity_columns(path, store: str = "recording") -> dict:
    """Per entity path: its columns (without row ids) merged over its chunks, static rows
    under ``(path, True)``, the others under ``(path, False)``; a column is the list of its
    rows, times in nanoseconds. ``store``: the ``"recording"`` or the ``"blueprint"``."""
    from rerun.chunk import RrdReader

    reader = RrdReader(path)
    entry = (reader.recordings() if store == "recording" else reader.blueprints())[0]
    data: dict = {}
    for chunk in reader.stream(store=entry):
        batch = chunk.to_record_batch()
        merged = data.setdefault((chunk.entity_path, chunk.is_static), {})
        for name in batch.schema.names:
            if name == "rerun.controls.RowId":
                continue
            column = batch.column(name)
            if pa.types.is_duration(column.type) or pa.types.is_timestamp(column.type):
                column = column.cast(pa.int64())  # nanoseconds
            merged.setdefault(name, []).extend(column.to_pylist())
    return data


def rgba(packed: int) -> tuple[int, int, int, int]:
    """A colour read back (``0xRRGGBBAA``) as ``(r, g, b, a)``."""
    return tuple(int(packed) >> shift & 0xFF for shift in (24, 16, 8, 0))  # type: ignore[return-value]


def only(rows: list):
    """The one value of a static component logged as one row of one instance."""
    assert len(rows) == 1 and len(rows[0]) == 1, rows
    return rows[0][0]


def annotation_classes(data: dict) -> dict[int, tuple[str, tuple]]:
    """The annotation context on ``/world`` read back: class id -> (label, rgba)."""
    context = data[("/world", True)]["AnnotationContext:context"]
    assert len(context) == 1
    return {
        entry["class_id"]: (
            entry["class_description"]["info"]["label"],
            rgba(entry["class_description"]["info"]["color"]),
        )
        for entry in only(context)
    }


def test_the_world_is_drawn_y_up(clamp_run):
    """The y-down 2-D view looks at ``/`` and ``/world`` carries ``y -> -y``: the map's top
    wall (largest y) is drawn at the top of the screen (smallest view y)."""
    spec, _, path = clamp_run
    data = entity_columns(path)
    matrix = np.array(only(data[("/world", True)]["Transform3D:mat3x3"])).reshape(3, 3)
    np.testing.assert_array_equal(matrix, np.diag([1.0, -1.0, 1.0]))  # symmetric: order moot
    walls = np.array(only_rows(data[("/world/map/walls", True)]["LineStrips2D:strips"]))
    np.testing.assert_allclose(walls, spec.map.segments)
    view_y = (walls.reshape(-1, 2) @ matrix[:2, :2].T)[:, 1]
    top = np.argmax(walls.reshape(-1, 2)[:, 1])
    assert view_y[top] == view_y.min()

    views = blueprint_views(path)
    (map_view,) = [v for v in views.values() if v["class"] == "2D"]
    # the transform applies: the view's origin is an ancestor of /world, its contents world
    assert map_view["origin"] == "/" and map_view["contents"] == ["/world/**"]
    x_range, y_range = map_view["bounds"]
    (x0, x1), (y0, y1) = spec.map.bounds
    assert x_range[0] < x0 and x1 < x_range[1]
    assert y_range[0] < -y1 and -y0 < y_range[1]  # the map, reflected, inside the bounds
    legend = np.array(only_rows(data[("/world/legend", True)]["Points2D:positions"]))
    assert (y_range[0] < -legend[:, 1]).all() and (-legend[:, 1] < y_range[1]).all()


def only_rows(rows: list) -> list:
    """The instances of a static component logged as one row."""
    assert len(rows) == 1, rows
    return rows[0]


#: Entities of the map and the component that holds what they draw.
DRAWN = {
    "LineStrips2D": "strips",
    "Points2D": "positions",
    "Boxes2D": "half_sizes",
    "Ellipses2D": "half_sizes",
    "Arrows2D": "vectors",
}


def test_every_thing_drawn_has_a_named_coloured_class(clamp_run):
    from scenarios.recording import CLASSES

    _, _, path = clamp_run
    data = entity_columns(path)
    classes = annotation_classes(data)
    assert classes == {c.id: (c.label, c.color) for c in CLASSES.values()}
    assert len({label for label, _ in classes.values()}) == len(classes)  # told apart by name
    names = {"truth", "ukf_only", "fused", "fused_box", "mcl", "outer_box", "hull", "echo"}
    assert names <= set(CLASSES) and {"cone_echo", "cone_no_echo", "inner_box"} <= set(CLASSES)
    world = {entity for entity, _ in data if entity.startswith("/world/")}
    used: set[int] = set()
    for entity in world:
        columns = {**data.get((entity, True), {}), **data.get((entity, False), {})}
        archetypes = {name.split(":")[0] for name in columns if ":" in name}
        drawn = [a for a in archetypes if f"{a}:{DRAWN.get(a)}" in columns]
        assert len(drawn) == 1, (entity, archetypes)
        ids = columns.get(f"{drawn[0]}:class_ids")
        assert ids, f"{entity} draws without a class"
        used |= {i for row in ids for i in (row or [])}
    assert used <= set(classes)
    expected = {CLASSES[n].id for n in names - {"mcl"}} | {CLASSES["wall"].id}
    assert expected <= used  # the run draws truth, both estimates, the clamp box, sets, echoes
    legend = data[("/world/legend", True)]
    assert set(only_rows(legend["Points2D:class_ids"])) == used  # the legend lists what is drawn
    assert only_rows(legend["Points2D:show_labels"]) == [True]


def test_series_are_styled_in_the_colours_of_the_map(clamp_run):
    from scenarios.recording import EPOCH_SERIES
    from scenarios.runner import BRANCHES

    _, _, path = clamp_run
    data = entity_columns(path)
    classes = annotation_classes(data)
    label_colour = dict(classes.values())
    for quantity in ("position_m", "heading_rad"):
        names = []
        for branch in BRANCHES:
            columns = data[(f"/errors/{quantity}/{branch}", False)]
            colours = {rgba(c) for row in columns["SeriesLines:colors"] for c in row}
            (name,) = {n for row in columns["SeriesLines:names"] for n in row}
            names.append(name)
            # the branch's colour in the map: the class whose label starts the series name
            (label,) = [label for label in label_colour if name.split(" (")[0] == label]
            assert colours == {label_colour[label]}, (quantity, branch)
        assert len(set(names)) == len(names)
    colours = set()
    for entity in EPOCH_SERIES:
        columns = data[(f"/{entity}", False)]
        rows = len(columns["Scalars:scalars"])
        assert len(columns["SeriesLines:names"]) == rows and all(columns["SeriesLines:names"])
        colours.add(columns["SeriesLines:colors"][0][0])
    steps = data[("/intervals/status", False)]["SeriesLines:interpolation_mode"]
    assert {value for row in steps for value in row} == {2}  # StepAfter: named steps
    assert "0 global" in data[("/intervals/status", False)]["SeriesLines:names"][0][0]


def test_coarse_epochs_are_in_the_recording(tmp_path):
    """A hall run under a budget of 24 boxes: its coarse epochs, as the epoch log has them,
    are read back from ``/intervals/coarse``, one scalar per epoch at the epoch's time, 1
    where coarse and 0 elsewhere."""
    import dataclasses

    from scenarios.recording import write_recording
    from scenarios.runner import run_scenario
    from scenarios.spec import load_scenario

    spec = load_scenario("hall").with_run(duration_s=8.0)
    # without the contractor, whose sets of hall fit in 24 boxes
    intervals = dataclasses.replace(spec.estimation.intervals, max_boxes=24, contractor=False)
    spec = dataclasses.replace(
        spec, estimation=dataclasses.replace(spec.estimation, intervals=intervals)
    )
    result = run_scenario(spec)
    epochs = result.estimation.epochs
    assert np.count_nonzero(epochs.coarse) > 0  # the budget bit
    path = tmp_path / "coarse.rrd"
    write_recording(path, spec, result.log, result.estimation)
    (columns,) = [c for rows, c in logged_data(path)[("/intervals/coarse", False)] if rows]
    read = np.array([row[0] for row in columns["Scalars:scalars"]])
    np.testing.assert_array_equal(read, epochs.coarse.astype(np.float64))
    times_ns = np.array(columns["time"], dtype=np.int64)
    np.testing.assert_array_equal(times_ns, np.round(epochs.t_s * 1e9).astype(np.int64))


def blueprint_views(path) -> dict[str, dict]:
    """The views of the recording's blueprint read back, by display name: class, origin,
    contents, visual bounds, time ranges and per-entity overrides."""
    data: dict = {}
    for (entity, _), columns in entity_columns(path, "blueprint").items():
        data.setdefault(entity, {}).update(columns)
    views = {}
    for entity, columns in data.items():
        if "ViewBlueprint:class_identifier" not in columns:
            continue

        def value(sub: str, name: str, view: str = entity):
            rows = data.get(f"{view}/{sub}", {}).get(name)
            return rows[-1][0] if rows and rows[-1] else None

        overrides = {
            key[len(f"{entity}/ViewContents/overrides") : -len("/visualizers")]: columns_
            for key, columns_ in data.items()
            if key.startswith(f"{entity}/ViewContents/overrides/")
        }
        bounds = value("VisualBounds2D", "VisualBounds2D:range")
        views[columns["ViewBlueprint:display_name"][-1][0]] = {
            "class": columns["ViewBlueprint:class_identifier"][-1][0],
            "origin": columns["ViewBlueprint:space_origin"][-1][0],
            "contents": data[f"{entity}/ViewContents"]["ViewContents:query"][-1],
            "bounds": (bounds["x_range"], bounds["y_range"]) if bounds else None,
            "time_ranges": value("VisibleTimeRanges", "VisibleTimeRanges:ranges"),
            "time_axis": value("TimeAxis", "TimeAxis:view_range"),
            "overrides": overrides,
        }
    return views


def time_panel(path) -> dict:
    """The time panel's settings in the recording's blueprint."""
    data: dict = {}
    for (entity, _), columns in entity_columns(path, "blueprint").items():
        if entity == "/time_panel":
            data.update(columns)
    return data


def test_the_blueprint_has_the_map_the_plots_by_unit_and_the_raw_sensors(clamp_run):
    from scenarios.recording import RAW_WINDOW_S, TRAIL_WINDOW_S

    _, _, path = clamp_run
    views = blueprint_views(path)
    panel = time_panel(path)
    assert panel["TimePanelBlueprint:timeline"] == [["time"]]
    assert panel["TimePanelBlueprint:play_state"] != [[2]]  # not playing at 1x
    plots = {name: v for name, v in views.items() if v["class"] == "TimeSeries"}
    # one unit per plot, named in its title
    unit = {tuple(v["contents"]): name.rsplit("(", 1)[-1].rstrip(")") for name, v in plots.items()}
    assert unit[("/errors/position_m/**",)] == "m" and unit[("/intervals/box_width_m",)] == "m"
    assert unit[("/errors/heading_rad/**",)] == "rad"
    assert unit[("/intervals/area_m2",)] == "m²" and unit[("/intervals/epoch_ms",)] == "ms"
    (status,) = [v for v in plots.values() if "/intervals/status" in v["contents"]]
    assert status["contents"] == ["/intervals/status", "/intervals/q_used", "/intervals/coarse"]
    # raw sensors in their own views, a window before the cursor; the others the whole run
    raw = [v for v in plots.values() if v["contents"][0].startswith(("/sensors", "/truth"))]
    assert {v["contents"][0].split("/")[1] for v in raw} == {"sensors", "truth"} and len(raw) == 5
    for view in plots.values():
        if view in raw:
            window = {"start": -round(RAW_WINDOW_S * 1e9), "end": 0}
            assert view["time_ranges"] == {"timeline": "time", "range": window}
            assert view["time_axis"] == window  # the axis follows the window
        else:
            assert view["time_ranges"] is None
            assert view["time_axis"] == {"start": None, "end": None}  # the whole run
    (notes,) = [v for v in views.values() if v["class"] == "TextDocument"]
    assert notes["origin"] == "notes/legend"
    (map_view,) = [v for v in views.values() if v["class"] == "2D"]
    overrides = map_view["overrides"]
    trails = {
        "/world/robot/trail",
        "/world/estimates/ukf_only/trail",
        "/world/estimates/fused/trail",
    }
    paths = {t.replace("trail", "path") for t in trails}
    assert set(overrides) == trails | paths
    for trail in trails:  # a window up to the cursor
        assert overrides[trail]["VisibleTimeRanges:ranges"] == [
            [{"timeline": "time", "range": {"start": -round(TRAIL_WINDOW_S * 1e9), "end": 0}}]
        ]
    for whole in paths:  # the optional faint layer, off by default
        assert overrides[whole]["EntityBehavior:visible"] == [[False]]


def test_the_epoch_time_axis_clips_only_the_slow_epochs():
    from types import SimpleNamespace

    from scenarios.recording import EPOCH_AXIS_FACTOR, epoch_axis

    def estimation(epoch_ms):
        epochs = SimpleNamespace(elapsed_s=np.asarray(epoch_ms, dtype=float) * 1e-3)
        return SimpleNamespace(epochs=epochs)

    typical = np.r_[np.full(99, 4.0), 5.0]
    assert epoch_axis(estimation(typical)) is None  # nothing off the scale
    axis = epoch_axis(estimation(np.r_[9000.0, typical]))  # a slow global epoch
    assert axis is not None
    bottom, top = axis
    assert bottom == 0.0 and top == pytest.approx(
        EPOCH_AXIS_FACTOR * np.percentile(np.r_[9000.0, typical], 95)
    )
    assert 5.0 < top < 9000.0
    assert epoch_axis(None) is None and epoch_axis(estimation([])) is None


def outline_rows(data: dict, branch: str):
    """The ``branch``'s outline strips ``(S, P, 2)``, class ids ``(S,)`` and times ``(S,)`` s."""
    columns = data[(f"/world/estimates/{branch}/ellipse", False)]
    strips = np.array([row[0] for row in columns["LineStrips2D:strips"]])
    ids = np.array([row[0] for row in columns["LineStrips2D:class_ids"]])
    return strips, ids, np.array(columns["time"]) * 1e-9


def test_the_fused_outline_under_the_clamp_is_the_box_it_was_clamped_to(clamp_run):
    """The clamp leaves the covariance: after the first clamp the fused branch shows the
    box of its last clamp, not the (UKF-only) covariance; the UKF-only branch its own
    2-sigma ellipse."""
    from scenarios.recording import CLASSES, ELLIPSE_SIGMA, ESTIMATE_STRIDE

    _, result, path = clamp_run
    est = result.estimation
    data = entity_columns(path)
    strips, ids, t_s = outline_rows(data, "fused")
    np.testing.assert_allclose(t_s, result.log.t_s[::ESTIMATE_STRIDE], atol=1e-9)
    clamp_t = result.log.t_s[est.epoch_index][est.component >= 0]
    boxes = est.fused_box[est.component >= 0]
    assert len(clamp_t) >= 2
    for strip, class_id, t in zip(strips, ids, t_s, strict=True):
        earlier = np.flatnonzero(clamp_t <= t + 1e-12)
        if len(earlier) == 0:
            assert class_id == CLASSES["fused"].id
            continue
        box = boxes[earlier[-1], :2]
        assert class_id == CLASSES["fused_box"].id
        np.testing.assert_allclose(strip.min(axis=0), box[:, 0])
        np.testing.assert_allclose(strip.max(axis=0), box[:, 1])
        on_side = np.isclose(strip[:, None, :], box[None, :, :].transpose(0, 2, 1)).any(axis=(1, 2))
        assert on_side.all()  # every point on the box's boundary
    assert (ids == CLASSES["fused_box"].id).sum() > len(ids) // 2

    strips, ids, _ = outline_rows(data, "ukf_only")
    assert (ids == CLASSES["ukf_only"].id).all()
    pose = est.pose[0, ::ESTIMATE_STRIDE]
    cov = est.pose_cov[0, ::ESTIMATE_STRIDE, :2, :2]
    d = strips - pose[:, None, :2]
    mahalanobis = np.einsum("spi,sij,spj->sp", d, np.linalg.inv(cov), d)
    np.testing.assert_allclose(mahalanobis, ELLIPSE_SIGMA**2, rtol=1e-5)


def test_the_fused_ellipse_under_truncation_is_the_covariance_it_leaves(truncated_run):
    """The truncated rule updates the covariance: the fused ellipse is that covariance's, and
    it is smaller than the UKF-only one once the boxes have been used."""
    from scenarios.recording import CLASSES, ELLIPSE_SIGMA, ESTIMATE_STRIDE

    _, result, path = truncated_run
    est = result.estimation
    data = entity_columns(path)
    strips, ids, _ = outline_rows(data, "fused")
    assert (ids == CLASSES["fused"].id).all()
    legend = only_rows(data[("/world/legend", True)]["Points2D:class_ids"])
    assert CLASSES["fused"].id in legend and CLASSES["fused_box"].id not in legend
    pose = est.pose[1, ::ESTIMATE_STRIDE]
    cov = est.pose_cov[1, ::ESTIMATE_STRIDE, :2, :2]
    d = strips - pose[:, None, :2]
    mahalanobis = np.einsum("spi,sij,spj->sp", d, np.linalg.inv(cov), d)
    np.testing.assert_allclose(mahalanobis, ELLIPSE_SIGMA**2, rtol=1e-5)
    ukf_area = np.sqrt(np.linalg.det(est.pose_cov[0, -1, :2, :2]))
    fused_area = np.sqrt(np.linalg.det(est.pose_cov[1, -1, :2, :2]))
    assert fused_area < ukf_area


def test_one_hull_per_connected_component(clamp_run):
    _, result, path = clamp_run
    epochs = result.estimation.epochs
    columns = entity_columns(path)[("/world/intervals/hull", False)]
    ends = np.cumsum(epochs.box_counts)
    assert len(columns["Boxes2D:centers"]) == len(epochs.t_s)
    for e, (centres, half) in enumerate(
        zip(columns["Boxes2D:centers"], columns["Boxes2D:half_sizes"], strict=True)
    ):
        boxes = epochs.boxes[ends[e] - epochs.box_counts[e] : ends[e], :2]
        labels = epochs.labels[ends[e] - epochs.box_counts[e] : ends[e]]
        expected = sorted(
            (
                tuple(boxes[labels == label, :, 0].min(axis=0)),
                tuple(boxes[labels == label, :, 1].max(axis=0)),
            )
            for label in np.unique(labels)
        )
        got = sorted(
            (tuple(np.subtract(c, h)), tuple(np.add(c, h)))
            for c, h in zip(centres or [], half or [], strict=True)
        )
        assert len(got) == epochs.components[e] == len(expected), e
        np.testing.assert_allclose(np.array(got), np.array(expected), atol=1e-5)


def test_the_trails_follow_the_paths_segment_by_segment(clamp_run):
    from scenarios.recording import TRAIL_STRIDE

    _, result, path = clamp_run
    data = entity_columns(path)
    for entity, xy in (
        ("/world/robot", result.log.pose[:, :2]),
        ("/world/estimates/ukf_only", result.estimation.pose[0, :, :2]),
        ("/world/estimates/fused", result.estimation.pose[1, :, :2]),
    ):
        columns = data[(f"{entity}/trail", False)]
        segments = np.array([row[0] for row in columns["LineStrips2D:strips"]])  # (S, 2, 2)
        shown = xy[::TRAIL_STRIDE]
        np.testing.assert_allclose(segments[:, 1], shown, atol=1e-5)
        np.testing.assert_allclose(segments[1:, 0], shown[:-1], atol=1e-5)
        np.testing.assert_allclose(np.array(columns["time"]) * 1e-9, result.log.t_s[::TRAIL_STRIDE])
        whole = only_rows(data[(f"{entity}/path", True)]["LineStrips2D:strips"])
        np.testing.assert_allclose(np.array(whole[0]), xy, atol=1e-5)


def free_port() -> int:
    import socket

    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


@pytest.mark.filterwarnings("ignore:RRD file has no footer")  # a stream saved as it came
def test_connect_streams_the_recording_and_its_blueprint_to_a_viewer(tmp_path):
    """``robotsim run --connect HOST:PORT`` streams to a running rerun server (here one that
    saves what it receives): the same entities and rows as the file, and the blueprint."""
    import os
    import signal
    import subprocess
    import sys
    import time
    from pathlib import Path

    from rerun.chunk import RrdReader

    port = free_port()
    received = tmp_path / "received.rrd"
    rerun_cli = str(Path(sys.executable).with_name("rerun"))
    server = subprocess.Popen(  # its own process group: the entry point runs the binary
        [rerun_cli, "--port", str(port), "--save", str(received)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    try:
        import socket

        deadline = time.monotonic() + 30
        while True:  # wait for the server to listen
            try:
                socket.create_connection(("127.0.0.1", port), timeout=1).close()
                break
            except OSError:
                assert time.monotonic() < deadline, "the rerun server did not start"
                time.sleep(0.2)
        robotsim = str(Path(sys.executable).with_name("robotsim"))
        rrd = tmp_path / "hall.rrd"
        done = subprocess.run(
            [
                *(robotsim, "run", "hall", "--duration", "2", "--rrd", str(rrd)),
                *("--summary", str(tmp_path / "hall.json"), "--connect", f"127.0.0.1:{port}"),
            ],
            cwd=tmp_path,
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert done.returncode == 0, done.stderr
        deadline = time.monotonic() + 30
        while not (received.exists() and received.stat().st_size > 0):
            assert time.monotonic() < deadline, "nothing received"
            time.sleep(0.2)
        time.sleep(1.0)
    finally:  # the whole group: terminating the entry point alone left the binary running
        os.killpg(server.pid, signal.SIGTERM)
        server.wait(timeout=30)

    def rows(path) -> dict:
        counts: dict = {}
        for (entity, static), columns in entity_columns(path).items():
            first: list = next(iter(columns.values()), [])
            counts[(entity, static)] = len(first)
        return counts

    assert rows(received) == rows(rrd)
    assert len(RrdReader(received).blueprints()) == 1
    assert blueprint_views(received).keys() == blueprint_views(rrd).keys()


def test_unmapped_obstacles_are_drawn_where_the_simulator_had_them(tmp_path):
    """``apartment_lived_in``: its still obstacles read back as static strips equal to their
    edges, its walking person as strips at the estimate samples equal to the obstacle's edges
    at those times (it moves), all in the ``obstacle`` class, which the legend lists."""
    from scenarios.recording import CLASSES, ESTIMATE_STRIDE, write_recording
    from scenarios.runner import run_scenario
    from scenarios.spec import load_scenario

    spec = load_scenario("apartment_lived_in").with_run(duration_s=4.0)
    assert len(spec.obstacles.static_edges_m) and spec.obstacles.moving
    result = run_scenario(spec)
    path = tmp_path / "lived_in.rrd"
    write_recording(path, spec, result.log, result.estimation)
    data = entity_columns(path)
    still = data[("/world/obstacles/static", True)]
    (strips,) = still["LineStrips2D:strips"]
    np.testing.assert_allclose(np.array(strips), spec.obstacles.static_edges_m, atol=1e-5)
    moving = data[("/world/obstacles/moving", False)]
    t_s = result.log.t_s[::ESTIMATE_STRIDE]
    np.testing.assert_array_equal(np.array(moving["time"]), np.round(t_s * 1e9).astype(np.int64))
    expected = spec.obstacles.moving_edges_m(t_s)
    read = np.array([np.array(row) for row in moving["LineStrips2D:strips"]])
    np.testing.assert_allclose(read, expected, rtol=0, atol=1e-5)  # float32 on the wire
    assert np.ptp(read[:, :, :, 0]) > 0.1 or np.ptp(read[:, :, :, 1]) > 0.1  # it moved
    obstacle = CLASSES["obstacle"].id
    assert {obstacle} == set(np.concatenate(moving["LineStrips2D:class_ids"]).tolist())
    assert obstacle in set(
        only(data[("/world/obstacles/static", True)]["LineStrips2D:class_ids"])
        if False
        else still["LineStrips2D:class_ids"][0]
    )
    legend = data[("/world/legend", True)]["Points2D:class_ids"][0]
    assert obstacle in legend
