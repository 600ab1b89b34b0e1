"""The built-in floor plans, drawn from a few parameters, and the WKT map files they give.

    python -m scenarios.builtin.make_plans           # (re)write scenarios/builtin/maps/*.wkt
    python -m scenarios.builtin.make_plans --check   # exit 1 if a committed file is stale

Each plan is an outer wall (a polygon, whose inside is the free space), interior walls
(line strings; a door is a gap between two of them) and furniture (closed polygons). Its
map file is one WKT ``GEOMETRYCOLLECTION``: the outer polygon first, then the walls, then
the furniture, coordinates in metres; ``robotsim.maps.SegmentMap.from_wkt`` reads it (the
largest polygon becomes the outer wall, every edge a segment). The scenario of each plan is
the hand-written ``scenarios/builtin/<name>.toml`` next to this file; its route is chosen
against the door and furniture positions below, so a change here may need a change there
(``tests/scenarios/test_builtin_plans.py`` checks the routes' clearance).

Plans (x east, y north, origin at the south-west corner):

- ``office_floor``: 50 x 40 m, 38 rooms along four corridors 2 m wide (a ring of two
  east-west corridors joined by two north-south ones), a 1 m door per room, a desk and a
  shelf in each room placed with a fixed seed, a round table in every third room.
- ``corridor``: 30 x 1.8 m, closed doors as 0.1 m deep niches at uneven places.
- ``apartment``: an L-shaped flat (12 x 5 m south wing, 7 x 4 m north wing): living room,
  kitchen, bedroom and bathroom, 0.9 m doors and a 1.2 m kitchen opening, furniture.
- ``cluttered_room``: 6 x 5 m with two tables, chairs and three shelves.
- ``big_hall``: a plain 60 x 60 m hall, four walls and nothing else.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from scenarios.outputs import write_text

#: Where the map files go: ``scenarios/builtin/maps/<name>.wkt``.
MAPS_DIR = Path(__file__).resolve().parent / "maps"

#: Width of a door gap in the office floor (m): the robot is 0.4 m across.
OFFICE_DOOR_M = 1.0

#: Door width in the apartment, m.
APARTMENT_DOOR_M = 0.9

#: Seed of the furniture placement in the office rooms (the plan is fixed, not random).
OFFICE_FURNITURE_SEED = 13

Point = tuple[float, float]


@dataclass
class Plan:
    """What a floor plan is made of, in metres.

    ``outer``: the outer wall's vertices ``[(x, y), ...]`` in order (not closed);
    ``walls``: interior walls, each a polyline ``[(x, y), ...]``;
    ``furniture``: closed obstacles, each a polygon's vertices in order.
    """

    outer: list[Point]
    walls: list[list[Point]] = field(default_factory=list)
    furniture: list[list[Point]] = field(default_factory=list)

    def segment_count(self) -> int:
        """Segments of the map: one per polygon edge and per polyline step."""
        return (
            len(self.outer)
            + sum(len(wall) - 1 for wall in self.walls)
            + sum(len(piece) for piece in self.furniture)
        )

    def wkt(self) -> str:
        """The plan as one WKT geometry collection, one geometry per line."""
        parts = [_polygon_wkt(self.outer)]
        parts += [f"LINESTRING ({_coords(wall)})" for wall in self.walls]
        parts += [_polygon_wkt(piece) for piece in self.furniture]
        return "GEOMETRYCOLLECTION (\n  " + ",\n  ".join(parts) + "\n)\n"


def _coords(points: list[Point]) -> str:
    return ", ".join(f"{_number(x)} {_number(y)}" for x, y in points)


def _number(value: float) -> str:
    """A coordinate to the millimetre, without trailing zeros (``3``, ``3.25``)."""
    text = f"{round(value, 3):.3f}".rstrip("0").rstrip(".")
    return "0" if text == "-0" else text


def _polygon_wkt(vertices: list[Point]) -> str:
    return f"POLYGON (({_coords([*vertices, vertices[0]])}))"


def rectangle(x0: float, y0: float, x1: float, y1: float) -> list[Point]:
    """Corners of ``[x0, x1] x [y0, y1]``, counter-clockwise from the south-west one."""
    return [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]


def regular_polygon(cx: float, cy: float, radius_m: float, sides: int) -> list[Point]:
    """A round table: ``sides`` vertices on the circle of ``radius_m`` about ``(cx, cy)``."""
    angles = 2.0 * math.pi * np.arange(sides) / sides
    return [(cx + radius_m * math.cos(a), cy + radius_m * math.sin(a)) for a in angles]


def wall_with_doors(
    start: Point, end: Point, door_centres_m: list[float], door_m: float
) -> list[list[Point]]:
    """The straight wall ``start -> end`` with a gap of ``door_m`` centred at each distance
    ``door_centres_m`` (m from ``start``, increasing): the pieces between the doors."""
    (ax, ay), (bx, by) = start, end
    length = math.hypot(bx - ax, by - ay)
    ux, uy = (bx - ax) / length, (by - ay) / length
    cuts = [0.0]
    for centre in door_centres_m:
        cuts += [centre - door_m / 2.0, centre + door_m / 2.0]
    cuts.append(length)
    return [
        [(ax + s * ux, ay + s * uy), (ax + t * ux, ay + t * uy)]
        for s, t in zip(cuts[0::2], cuts[1::2], strict=True)
        if t - s > 1e-9
    ]


# Office floor ---------------------------------------------------------------------------


@dataclass(frozen=True)
class RoomRow:
    """A block ``[x0, x1] x [y0, y1]`` cut into ``rooms`` equal rooms side by side along its
    door wall, the side ``door_side`` (``"S"``, ``"N"``, ``"W"``, ``"E"``) that faces a
    corridor. In a room's own frame, ``u`` runs along the door wall from the room's first
    corner and ``w`` is the depth from the door wall into the room."""

    x0: float
    y0: float
    x1: float
    y1: float
    door_side: str
    rooms: int

    @property
    def along_m(self) -> tuple[float, float]:
        """The block's extent along the door wall, m (start, end)."""
        return (self.x0, self.x1) if self.door_side in "SN" else (self.y0, self.y1)

    @property
    def room_width_m(self) -> float:
        start, end = self.along_m
        return (end - start) / self.rooms

    @property
    def depth_m(self) -> float:
        return (self.y1 - self.y0) if self.door_side in "SN" else (self.x1 - self.x0)

    def world(self, room: int, u: float, w: float) -> Point:
        """World point of ``(u, w)`` in room ``room``."""
        along = self.along_m[0] + room * self.room_width_m + u
        if self.door_side == "S":
            return (along, self.y0 + w)
        if self.door_side == "N":
            return (along, self.y1 - w)
        if self.door_side == "W":
            return (self.x0 + w, along)
        return (self.x1 - w, along)

    def box(self, room: int, u0: float, w0: float, u1: float, w1: float) -> list[Point]:
        """The room-frame rectangle ``[u0, u1] x [w0, w1]`` as a world polygon."""
        corners = [(u0, w0), (u1, w0), (u1, w1), (u0, w1)]
        return [self.world(room, u, w) for u, w in corners]

    def door_centre(self, room: int) -> Point:
        """Centre of room ``room``'s door, on the door wall (1 m from the room's first corner)."""
        return self.world(room, 1.0, 0.0)


def _office_row(row: RoomRow, rng: np.random.Generator, first_room: int) -> Plan:
    """The door wall, the dividers and the furniture of one row of office rooms.

    Each room's door is at ``u`` 0.5 to 1.5 m and the strip ``u < 1.7`` m is kept clear but
    for the shelf at the back wall (the routes go 3.5 m in along ``u = 1``): a desk
    (1.6 x 0.8 m) at ``u >= 2.1``, ``w`` 2.5 to ``depth - 2.8`` m, a shelf (1.4 x 0.4 m)
    against the back wall, and in every third room (counted over the floor) a round table
    (0.5 m radius, eight sides) centred 1.6 m from the back wall.
    """
    width, depth = row.room_width_m, row.depth_m
    door_wall = (row.world(0, 0.0, 0.0), row.world(row.rooms - 1, width, 0.0))
    centres = [room * width + 1.0 for room in range(row.rooms)]
    plan = Plan(outer=[], walls=wall_with_doors(*door_wall, centres, OFFICE_DOOR_M))
    for room in range(1, row.rooms):
        plan.walls.append([row.world(room, 0.0, 0.0), row.world(room, 0.0, depth)])
    for room in range(row.rooms):
        desk_u = rng.uniform(2.1, width - 1.8)
        desk_w = rng.uniform(2.5, depth - 3.6)
        plan.furniture.append(row.box(room, desk_u, desk_w, desk_u + 1.6, desk_w + 0.8))
        shelf_u = rng.uniform(0.3, width - 1.7)
        plan.furniture.append(row.box(room, shelf_u, depth - 0.5, shelf_u + 1.4, depth - 0.1))
        if (first_room + room) % 3 == 0:
            cx, cy = row.world(room, width / 2.0, depth - 1.6)
            plan.furniture.append(regular_polygon(cx, cy, 0.5, 8))
    return plan


#: The office floor's rows of rooms (corridors: y 9-11 and 29-31 east-west, x 12-14 and
#: 36-38 north-south between them). Their names are used by the scenario comments.
OFFICE_ROWS = {
    "south": RoomRow(0.0, 0.0, 50.0, 9.0, "N", 10),
    "north": RoomRow(0.0, 31.0, 50.0, 40.0, "S", 10),
    "centre_south": RoomRow(14.0, 11.0, 36.0, 20.0, "S", 5),
    "centre_north": RoomRow(14.0, 20.0, 36.0, 29.0, "N", 5),
    "west": RoomRow(0.0, 11.0, 12.0, 29.0, "E", 4),
    "east": RoomRow(38.0, 11.0, 50.0, 29.0, "W", 4),
}


def office_floor() -> Plan:
    """50 x 40 m office floor: 38 rooms round a ring of 2 m corridors (see the module doc)."""
    plan = Plan(outer=rectangle(0.0, 0.0, 50.0, 40.0))
    # walls without doors: the corridor sides of the west and east blocks, the sides of the
    # centre block along the north-south corridors, and the centre block's middle wall
    plan.walls += [
        [(0.0, 11.0), (12.0, 11.0)],
        [(38.0, 11.0), (50.0, 11.0)],
        [(0.0, 29.0), (12.0, 29.0)],
        [(38.0, 29.0), (50.0, 29.0)],
        [(14.0, 11.0), (14.0, 29.0)],
        [(36.0, 11.0), (36.0, 29.0)],
        [(14.0, 20.0), (36.0, 20.0)],
    ]
    rng = np.random.default_rng(OFFICE_FURNITURE_SEED)
    first_room = 0
    for row in OFFICE_ROWS.values():
        part = _office_row(row, rng, first_room)
        plan.walls += part.walls
        plan.furniture += part.furniture
        first_room += row.rooms
    return plan


# The other plans ------------------------------------------------------------------------


def corridor() -> Plan:
    """30 x 1.8 m corridor; closed doors are niches 0.9 m wide and 0.1 m deep in its walls,
    four on the south side and three on the north side, at uneven places."""
    length, width, door, depth = 30.0, 1.8, 0.9, 0.1
    south_doors = [3.2, 9.0, 17.5, 24.1]
    north_doors = [5.6, 13.3, 26.4]
    south: list[Point] = [(0.0, 0.0)]
    for centre in south_doors:
        a, b = centre - door / 2.0, centre + door / 2.0
        south += [(a, 0.0), (a, -depth), (b, -depth), (b, 0.0)]
    south.append((length, 0.0))
    north: list[Point] = [(length, width)]
    for centre in reversed(north_doors):
        a, b = centre + door / 2.0, centre - door / 2.0
        north += [(a, width), (a, width + depth), (b, width + depth), (b, width)]
    north.append((0.0, width))
    return Plan(outer=south + north)


def apartment() -> Plan:
    """L-shaped flat: a 12 x 5 m south wing (living room west of x = 7, kitchen east) and a
    7 x 4 m north wing (bedroom west of x = 4, bathroom east), with furniture."""
    plan = Plan(outer=[(0.0, 0.0), (12.0, 0.0), (12.0, 5.0), (7.0, 5.0), (7.0, 9.0), (0.0, 9.0)])
    plan.walls += wall_with_doors((0.0, 5.0), (7.0, 5.0), [3.2, 5.5], APARTMENT_DOOR_M)
    plan.walls.append([(4.0, 5.0), (4.0, 9.0)])  # bedroom | bathroom
    plan.walls += wall_with_doors((7.0, 0.0), (7.0, 5.0), [2.6], 1.2)  # living | kitchen
    plan.furniture += [
        rectangle(0.6, 0.2, 2.8, 1.1),  # sofa against the south wall
        rectangle(1.2, 1.8, 2.2, 2.4),  # coffee table
        rectangle(0.1, 2.9, 0.5, 4.4),  # TV cabinet on the west wall
        rectangle(4.6, 0.8, 5.8, 1.7),  # dining table
        rectangle(11.4, 0.4, 11.9, 4.6),  # kitchen counter on the east wall
        rectangle(9.2, 1.8, 10.4, 2.6),  # kitchen island
        rectangle(0.2, 6.4, 1.8, 8.8),  # double bed
        rectangle(3.3, 7.3, 3.9, 8.9),  # wardrobe
        rectangle(5.1, 8.1, 6.9, 8.9),  # bathtub
        rectangle(6.4, 5.6, 6.9, 6.4),  # washbasin
    ]
    return plan


def cluttered_room() -> Plan:
    """6 x 5 m room: two tables with chairs, three shelves against the walls, a cabinet."""
    plan = Plan(outer=rectangle(0.0, 0.0, 6.0, 5.0))
    plan.furniture += [
        rectangle(1.2, 1.3, 2.4, 2.1),  # table 1
        rectangle(1.5, 2.2, 1.95, 2.6),  # its chair
        rectangle(3.5, 3.0, 4.7, 3.8),  # table 2
        rectangle(3.9, 3.85, 4.35, 4.3),  # its chairs
        rectangle(4.8, 3.1, 5.2, 3.55),
        rectangle(0.1, 2.9, 0.5, 4.8),  # shelf on the west wall
        rectangle(5.5, 0.2, 5.9, 1.9),  # shelf on the east wall
        rectangle(1.8, 4.5, 3.2, 4.9),  # shelf on the north wall
        rectangle(5.5, 2.6, 5.9, 3.8),  # cabinet on the east wall
    ]
    return plan


def big_hall() -> Plan:
    """A plain 60 x 60 m hall: four walls, nothing inside (large and symmetric by nature)."""
    return Plan(outer=rectangle(0.0, 0.0, 60.0, 60.0))


#: The plans by name: the map file ``maps/<name>.wkt`` and the scenario ``<name>.toml``.
PLANS: dict[str, Callable[[], Plan]] = {
    "office_floor": office_floor,
    "corridor": corridor,
    "apartment": apartment,
    "cluttered_room": cluttered_room,
    "big_hall": big_hall,
}


def map_path(name: str) -> Path:
    """The map file of plan ``name``."""
    return MAPS_DIR / f"{name}.wkt"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--check", action="store_true", help="only compare with the committed files"
    )
    args = parser.parse_args(argv)
    stale = []
    for name, make in PLANS.items():
        plan, path = make(), map_path(name)
        text = plan.wkt()
        if args.check:
            if not path.is_file() or path.read_text(encoding="utf-8") != text:
                stale.append(path)
            continue
        path.parent.mkdir(exist_ok=True)
        write_text(path, text)
        print(f"{path}: {plan.segment_count()} segments")
    for path in stale:
        print(f"stale or missing: {path} (run python -m scenarios.builtin.make_plans)")
    return 1 if stale else 0


if __name__ == "__main__":
    sys.exit(main())
