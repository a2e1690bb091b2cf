"""Named simulation scenarios and the route each one drives.

A scenario fixes the family of buildings (:class:`~slam.sim.world.RingSpec`) and the nominal log
length; the seed picks one building and one route in that family. The route leaves the origin
along the bottom corridor heading +x, makes a detour into some rooms (through their doors, around
the room, back out), goes once around the ring corridor counter-clockwise and drives a few metres
past the start again, so every log closes a loop.

* ``demo``: the size of the course's dataset20 (≈124 s at 40 Hz, ≈4960 scans), a floor of about
  18 × 22 m with 4–8 rooms;
* ``small``: a short loop (45 s) around a one-room block, for tests and quick experiments.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from slam.errors import UsageError
from slam.sim.trajectory import DriveLimits, Trajectory, drive, fillet_path, speed_profile
from slam.sim.trajectory import travel_time as _travel_time
from slam.sim.world import Layout, RingSpec, World, build_world, ring_layout, room_inset

F64 = NDArray[np.float64]

RING_CORNER_RADIUS = 1.0
"""Fillet radius at the ring corridor's corners (m)."""
DOOR_TURN_RADIUS = 0.6
"""Fillet radius where the route turns from a corridor into a door (m)."""
ROOM_TURN_RADIUS = 0.6
"""Fillet radius of the loop inside a room (m)."""
LOOP_WIDTH = 3.5
"""Largest extent of the loop a route drives inside a room, along the door's wall (m)."""
LOOP_DEPTH = 2.5
"""Largest depth of that loop into the room (m)."""
ROBOT_RADIUS = 0.35
"""Clearance the driven path keeps from every obstacle (m): half the robot's diagonal."""


@dataclass(frozen=True)
class Scenario:
    """A family of simulated logs: building sizes, nominal duration and default seed."""

    name: str
    description: str
    duration: float
    """Nominal log length (s)."""
    spec: RingSpec = field(default_factory=RingSpec)
    seed: int = 0
    """Default seed of ``slam sim``."""
    limits: DriveLimits = field(default_factory=DriveLimits)


SCENARIOS: dict[str, Scenario] = {
    "demo": Scenario(
        name="demo",
        description="dataset20-sized log (124 s) in a ring building with 4-8 rooms",
        duration=124.0,
        spec=RingSpec(),
        seed=20,
    ),
    "small": Scenario(
        name="small",
        description="short loop (45 s) around a one-room block, for tests",
        duration=45.0,
        spec=RingSpec(
            inner_x=(6.0, 7.0),
            inner_y=(3.5, 4.0),
            corridor_width=(1.9, 2.1),
            start_offset=(2.0, 2.5),
            inner_rooms=(1, 1),
            top_rooms=(1, 1),
            bottom_rooms=(0, 0),
            outer_depth=(3.5, 4.0),
        ),
        seed=1,
    ),
}


def get_scenario(name: str) -> Scenario:
    """The scenario called ``name``; :class:`UsageError` listing the known ones otherwise."""
    try:
        return SCENARIOS[name]
    except KeyError:
        raise UsageError(
            f"unknown simulation scenario {name!r}; expected one of {', '.join(SCENARIOS)}"
        ) from None


@dataclass(frozen=True)
class Route:
    """Waypoints and fillet radii of a route, and which rooms it visits."""

    waypoints: F64
    radii: F64
    visited: tuple[int, ...]
    """Indices (into ``layout.rooms``) of the rooms the route enters."""


def _room_loop(layout: Layout, room_index: int, clockwise: bool) -> tuple[list, list]:
    """Waypoints (and radii) of a detour: corridor → door → around the room → door → corridor."""
    room = layout.rooms[room_index]
    door = room.door
    t = layout.wall_thickness
    h = layout.corridor_width / 2
    nx, ny = door.normal
    cx, cy = door.centre
    inset = room_inset(room.rect)
    corridor_pt = (cx - nx * (h + t / 2), cy - ny * (h + t / 2))
    door_in = (cx + nx * (t / 2 + inset), cy + ny * (t / 2 + inset))
    # The loop covers at most LOOP_WIDTH × LOOP_DEPTH of the room, centred on the door.
    x0, y0, x1, y1 = (room.rect[0] + inset, room.rect[1] + inset, room.rect[2] - inset,
                      room.rect[3] - inset)  # fmt: skip
    if abs(ny) > 0.5:
        half = min(LOOP_WIDTH, x1 - x0) / 2
        mid = float(np.clip(door_in[0], x0 + half, x1 - half))
        x0, x1 = mid - half, mid + half
        if ny > 0:
            y1 = min(y1, y0 + LOOP_DEPTH)
        else:
            y0 = max(y0, y1 - LOOP_DEPTH)
    else:
        half = min(LOOP_WIDTH, y1 - y0) / 2
        mid = float(np.clip(door_in[1], y0 + half, y1 - half))
        y0, y1 = mid - half, mid + half
        if nx > 0:
            x1 = min(x1, x0 + LOOP_DEPTH)
        else:
            x0 = max(x0, x1 - LOOP_DEPTH)
    corners = [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]
    # Edge of the inset rectangle holding door_in (ccw numbering: bottom 0, right 1, top 2, left 3).
    if ny > 0.5:
        edge = 0
    elif ny < -0.5:
        edge = 2
    elif nx > 0.5:
        edge = 3
    else:
        edge = 1
    if clockwise:
        seq = [corners[(edge - k) % 4] for k in range(4)]
    else:
        seq = [corners[(edge + 1 + k) % 4] for k in range(4)]
    pts = [corridor_pt, door_in, *seq, door_in, corridor_pt]
    radii = [DOOR_TURN_RADIUS, 0.55] + [ROOM_TURN_RADIUS] * 4 + [0.55, DOOR_TURN_RADIUS]
    return pts, radii


def build_route(layout: Layout, detours: list[tuple[int, bool]], overlap: float) -> Route:
    """The loop around the ring with ``detours`` (room index, clockwise) inserted in order."""
    by_leg: dict[int, list[tuple[float, int, bool]]] = {}
    index = {id(room): k for k, room in enumerate(layout.rooms)}
    chosen = dict(detours)
    for leg, along, room in layout.loop_doors:
        k = index[id(room)]
        if k in chosen:
            by_leg.setdefault(leg, []).append((along, k, chosen[k]))
    pts: list = [layout.loop[0]]
    radii: list = [0.0]
    visited = []
    for leg in range(len(layout.loop) - 1):
        for _along, k, cw in sorted(by_leg.get(leg, [])):
            p, r = _room_loop(layout, k, cw)
            pts += p
            radii += r
            visited.append(k)
        pts.append(layout.loop[leg + 1])
        radii.append(RING_CORNER_RADIUS)
    end = layout.loop[-1]
    pts.append((end[0] + overlap, end[1]))
    radii.append(0.0)
    return Route(np.asarray(pts, dtype=np.float64), np.asarray(radii), tuple(visited))


def repeat_laps(route: Route, laps: int) -> tuple[F64, F64]:
    """The waypoints and fillet radii of ``route`` driven ``laps >= 1`` times: each lap but the
    last ends at the start (the ring's loop closes there, on a straight stretch of the bottom
    leg), the next goes on from it with the same detours, and the last drives past the start as
    the route does. One lap is the route itself."""
    if laps <= 1:
        return route.waypoints, route.radii
    lap = slice(1, -1)  # without the start, which the previous lap ends on, and the overlap
    waypoints = [route.waypoints[:-1], *[route.waypoints[lap]] * (laps - 2), route.waypoints[1:]]
    radii = [route.radii[:-1], *[route.radii[lap]] * (laps - 2), route.radii[1:]]
    return np.concatenate(waypoints), np.concatenate(radii)


def plan_route(
    layout: Layout, rng: np.random.Generator, duration: float, limits: DriveLimits
) -> Route:
    """Choose room detours so the route fits ``duration`` at a brisk cruise speed (0.9 m/s)."""
    xr = layout.loop[1][0]
    overlap = float(min(4.0, max(1.0, 0.5 * xr)))
    order = rng.permutation(len(layout.rooms))
    detours: list[tuple[int, bool]] = []
    door_x: dict[int, list[float]] = {}
    leg_of = {id(room): leg for leg, _, room in layout.loop_doors}
    budget = duration - 3.0
    for k in order:
        room = layout.rooms[int(k)]
        leg = leg_of[id(room)] % 4
        cx = room.door.centre[0]
        if any(abs(cx - other) < 2.5 for other in door_x.get(leg, [])):
            continue
        trial = [*detours, (int(k), bool(rng.uniform() < 0.5))]
        route = build_route(layout, trial, overlap)
        if _route_time(route, 0.9, limits) <= budget:
            detours = trial
            door_x.setdefault(leg, []).append(cx)
    return build_route(layout, detours, overlap)


def _route_time(route: Route, cruise: float, limits: DriveLimits) -> float:
    path, curvature = fillet_path(route.waypoints, route.radii)
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(path, axis=0).T))])
    return _travel_time(arc, speed_profile(arc, curvature, cruise, limits), limits)


@dataclass(frozen=True)
class Scene:
    """A generated world with the trajectory driven through it."""

    world: World
    trajectory: Trajectory
    route: Route
    info: dict
    """Planner summary: cruise speed, lengths, tracking error, clearance, rooms visited."""


def generate_scene(
    scenario: Scenario, rng: np.random.Generator, duration: float | None = None, t0: float = 0.0
) -> Scene:
    """Lay out a building, plan and drive a route through it, then furnish and paint it.

    Clutter is placed after driving, at a clearance from the driven path, so the robot never
    collides; the clearance to walls is checked here (a failure is a generator bug).
    """
    duration = scenario.duration if duration is None else float(duration)
    if not math.isfinite(duration) or duration <= 0:
        raise UsageError(f"--duration: expected a positive number of seconds, found {duration}")
    layout = ring_layout(scenario.spec, rng)
    route = plan_route(layout, rng, scenario.duration, scenario.limits)
    # The route is planned for the scenario's nominal duration; another duration keeps the route
    # and its speed: a shorter log is cut short, a longer one drives it lap after lap, cut where
    # the log ends (a lap takes at least its length at the cruise speed: one more than fit).
    trajectory, info = drive(route.waypoints, route.radii, scenario.duration, t0, scenario.limits)
    if duration != scenario.duration:
        lap = info["route_length_m"] - float(np.hypot(*np.diff(route.waypoints[-2:], axis=0)[0]))
        laps = (
            1
            if duration < scenario.duration
            else math.ceil(duration * info["cruise_speed"] / lap) + 1
        )
        waypoints, radii = repeat_laps(route, laps)
        trajectory, info = drive(
            waypoints, radii, duration, t0, scenario.limits, cruise=info["cruise_speed"]
        )
    path_xy = np.concatenate([trajectory.sample_xy(0.02), info["reference_path"]])
    world = build_world(rng, layout, path_xy)
    clearance = _clearance(world, trajectory)
    if clearance < ROBOT_RADIUS:
        raise RuntimeError(
            f"simulator bug: scenario {scenario.name!r} drives within {clearance:.2f} m of an "
            f"obstacle (needs {ROBOT_RADIUS} m)"
        )
    info = {k: v for k, v in info.items() if k != "reference_path"}
    info.update(
        clearance_m=clearance,
        rooms_visited=len(route.visited),
        rooms=len(layout.rooms),
        corridor_width_m=layout.corridor_width,
    )
    return Scene(world, trajectory, route, info)


def _clearance(world: World, trajectory: Trajectory) -> float:
    """Smallest distance (m) from the driven path to an obstacle cell."""
    dist = world.obstacle_distance()
    xy = trajectory.sample_xy(0.01)
    row, col = world.cell_of(xy[:, 0], xy[:, 1])
    return float(dist[row, col].min())
