"""Pictures of the built-in scenarios' plans: walls, route and start pose, one PNG each.

    python -m scenarios.builtin.draw_plans docs/plans/ [NAME ...]

Writes ``<folder>/<name>.png`` for each built-in scenario (default: all of them), drawn
from the map the scenario loads (``robotsim.maps.SegmentMap``: every segment as a wall),
its route (the waypoints from the start, closed when it loops) and its start pose, with
the sonar's reach ``d_max`` drawn round the start for scale; the unmapped obstacles of
``[world]`` in orange where they start, a moving one's sweep shaded. All the files are written or
none (``scenarios.outputs.atomic_paths``); other files in the folder are left alone.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

from robotsim.control import Route
from scenarios.outputs import atomic_paths
from scenarios.spec import ScenarioSpec, builtin_names, load_scenario

#: Longest side of a picture, inches (at :data:`DPI`).
FIGURE_INCHES = 9.0
DPI = 110


def route_points(spec: ScenarioSpec) -> np.ndarray:
    """The route's path ``(p, 2)`` metres: the start, the waypoints, and the start again
    (closing the loop through the first waypoint) when the route loops; the start alone
    for a scripted profile."""
    start = np.array(spec.start_pose[:2])[None]
    if not isinstance(spec.plan, Route):
        return start
    waypoints = np.asarray(spec.plan.waypoints_m)
    points = np.concatenate([start, waypoints])
    if spec.plan.loop:
        points = np.concatenate([points, waypoints[:1]])
    return points


def draw(spec: ScenarioSpec, path: Path) -> None:
    """One PNG of ``spec``'s plan at ``path``."""
    from matplotlib.collections import LineCollection
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle, Polygon

    segment_map = spec.map
    (x0, x1), (y0, y1) = segment_map.bounds
    margin = 0.04 * max(x1 - x0, y1 - y0)
    scale = FIGURE_INCHES / max(x1 - x0, y1 - y0)
    size = (max(4.0, scale * (x1 - x0)) + 1.0, max(2.2, scale * (y1 - y0)) + 1.2)
    figure = Figure(figsize=size, dpi=DPI)
    axes = figure.add_subplot()
    if segment_map.boundary is not None:
        axes.add_patch(Polygon(segment_map.boundary, closed=True, color="#f3f1ea", zorder=0))
    walls = LineCollection(list(segment_map.segments), colors="#222222", linewidths=1.4, zorder=2)
    axes.add_collection(walls)
    for obstacle in spec.obstacles.items:
        if obstacle.moving:
            swept = obstacle.swept()
            for part in getattr(swept, "geoms", [swept]):
                axes.add_patch(
                    Polygon(np.array(part.exterior.coords), color="#ff7f0e", alpha=0.25, zorder=1)
                )
        if obstacle.polygon:
            axes.add_patch(Polygon(obstacle.vertices_m, closed=True, color="#ff7f0e", zorder=2))
        else:
            axes.plot(*obstacle.vertices_m.T, color="#ff7f0e", linewidth=2.0, zorder=2)
    route = route_points(spec)
    axes.plot(*route.T, color="#1f77b4", linewidth=1.0, zorder=3)
    axes.plot(*route[1:].T, "o", color="#1f77b4", markersize=2.5, zorder=3)
    x, y, heading = spec.start_pose
    reach = spec.sensors.sonar.d_max_m
    axes.add_patch(
        Circle((x, y), reach, fill=False, linestyle="--", color="#d62728", linewidth=0.8, zorder=3)
    )
    axes.add_patch(Circle((x, y), spec.robot.radius_m, color="#d62728", zorder=4))
    arrow = 2.0 * spec.robot.radius_m
    axes.annotate(
        "",
        xy=(x + arrow * math.cos(heading), y + arrow * math.sin(heading)),
        xytext=(x, y),
        arrowprops={"arrowstyle": "->", "color": "#d62728", "linewidth": 1.2},
        zorder=4,
    )
    axes.set_xlim(x0 - margin, x1 + margin)
    axes.set_ylim(y0 - margin, y1 + margin)
    axes.set_aspect("equal")
    axes.set_xlabel("x (m)")
    axes.set_ylabel("y (m)")
    axes.set_title(
        f"{spec.name}: {x1 - x0:g} x {y1 - y0:g} m, {len(segment_map.segments)} segments\n"
        f"blue: route; red: start pose and the sonar's {reach:g} m reach"
        + ("; orange: unmapped obstacles, a moving one's sweep shaded" if spec.obstacles else ""),
        fontsize=9,
    )
    figure.savefig(path, format="png", bbox_inches="tight")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path, help="where the PNG files go")
    parser.add_argument("names", nargs="*", help="built-in scenarios (default: all)")
    args = parser.parse_args(argv)
    names = args.names or list(builtin_names())
    unknown = [name for name in names if name not in builtin_names()]
    if unknown:
        parser.error(f"unknown built-in scenario {unknown[0]!r}")
    args.folder.mkdir(parents=True, exist_ok=True)
    paths = [args.folder / f"{name}.png" for name in names]
    with atomic_paths(*paths) as temporaries:
        for name, temporary in zip(names, temporaries, strict=True):
            draw(load_scenario(name), temporary)
    for path in paths:
        print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
