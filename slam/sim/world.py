"""Procedural indoor worlds: a building as an occupancy grid plus a floor texture.

The simulator's world *is* a grid: ``labels[row, col]`` at ``resolution`` metres (row = y index,
column = x index, ``origin`` = world (x, y) of the lower-left corner of cell (0, 0)), 0 for free
floor and :data:`WALL`, :data:`FURNITURE` or :data:`PILLAR` for obstacles, every obstacle extruded
from the floor to ``wall_height``. Lidar beams and camera rays are cast against exactly this grid,
so the ground-truth map is exact by construction. The floor texture is a second grid (finer, same
origin convention) of RGB colours; ``floor`` marks texels that are visible floor.

This module owns the building layout (:func:`ring_layout`: a ring corridor — the loop — with
rooms inside and outside it, doors and a route through them), its rasterisation, clutter placement
away from the robot's path (:func:`place_clutter`), the floor painting (tiles, planks, rugs,
coloured patches, painted lines) and buildings grown around a given path (:func:`world_around_path`,
used by the dataset20 test fixture).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

from slam.grid_geometry import GridGeometry, Rect, covering

FREE = 0
WALL = 1
FURNITURE = 2
PILLAR = 3

LABEL_COLORS = np.array(
    [[0, 0, 0], [214, 220, 240], [40, 70, 140], [200, 235, 240]], dtype=np.float64
)
"""Plain RGB colour of each obstacle label in camera images (index 0 unused)."""

OUTSIDE_COLOR = np.array([20.0, 20.0, 24.0])
"""RGB colour of camera rays that hit nothing."""


@dataclass(frozen=True)
class World:
    """A simulated building: obstacle grid, floor texture and their geometry."""

    labels: NDArray[np.uint8]
    """``(H, W)`` cell labels: 0 free floor, 1 wall, 2 furniture, 3 pillar."""
    resolution: float
    """Cell size (m)."""
    origin: tuple[float, float]
    """World (x, y) of the lower-left corner of cell (0, 0)."""
    interior: NDArray[np.bool_]
    """``(H, W)`` cells inside the building (free or obstacle); outside is never seen."""
    texture: NDArray[np.uint8]
    """``(Ht, Wt, 3)`` floor colour (RGB) of each texel."""
    texture_resolution: float
    """Texel size (m)."""
    texture_origin: tuple[float, float]
    """World (x, y) of the lower-left corner of texel (0, 0)."""
    floor: NDArray[np.bool_]
    """``(Ht, Wt)`` texels that are visible floor (inside the building, not under an obstacle)."""
    wall_height: float = 2.5
    """Height of every obstacle (m)."""
    meta: dict = field(default_factory=dict)
    """Layout facts (rooms, doors, corridor width) for documentation and tests."""

    @property
    def occupancy(self) -> NDArray[np.uint8]:
        """``(H, W)`` uint8: 1 where an obstacle is, else 0."""
        return (self.labels != FREE).astype(np.uint8)

    @property
    def geometry(self) -> GridGeometry:
        """Where the obstacle grid ``labels`` lies."""
        return GridGeometry.of(self.origin, self.resolution, self.labels.shape)

    @property
    def texture_geometry(self) -> GridGeometry:
        """Where the floor texture lies."""
        return GridGeometry.of(self.texture_origin, self.texture_resolution, self.texture.shape)

    def cell_of(self, x: NDArray, y: NDArray) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """Row and column of the cells containing world points (may fall outside the grid)."""
        return self.geometry.cell_of(x, y)

    def texel_of(self, x: NDArray, y: NDArray) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """Row and column of the texels containing world points (may fall outside)."""
        return self.texture_geometry.cell_of(x, y)

    def obstacle_distance(self) -> NDArray[np.float32]:
        """``(H, W)`` distance (m) from each cell centre to the nearest obstacle cell."""
        free = (self.labels == FREE).astype(np.uint8)
        return cv2.distanceTransform(free, cv2.DIST_L2, cv2.DIST_MASK_PRECISE) * self.resolution


# ------------------------------------------------------------------------------------- grids


# ------------------------------------------------------------------------------------ layout


@dataclass(frozen=True)
class Door:
    """An opening in a wall between a corridor and a room."""

    centre: tuple[float, float]
    """Centre of the opening, on the wall's mid-line."""
    normal: tuple[float, float]
    """Unit vector across the wall, pointing into the room."""
    width: float
    """Opening width (m)."""


@dataclass(frozen=True)
class Room:
    """A rectangular room (its free interior) reached through one door."""

    rect: Rect
    door: Door
    kind: str
    """``"inner"`` (inside the ring) or ``"outer"``."""


@dataclass
class Layout:
    """Free areas, doors and rooms of a building, plus the corridor loop the robot follows."""

    corridors: list[Rect]
    rooms: list[Room]
    wall_thickness: float
    corridor_width: float
    loop: list[tuple[float, float]]
    """Corridor centreline corners in driving order, starting and ending at the origin."""
    loop_doors: list[tuple[int, float, Room]] = field(default_factory=list)
    """Doors reachable from the loop: (leg index, distance along that leg, room)."""

    def bounds(self) -> Rect:
        """Bounding box of every free area (m)."""
        rects = self.corridors + [room.rect for room in self.rooms]
        return (
            min(r[0] for r in rects),
            min(r[1] for r in rects),
            max(r[2] for r in rects),
            max(r[3] for r in rects),
        )

    def door_rect(self, door: Door) -> Rect:
        """The rectangle to carve for a door (spanning the wall and a little beyond)."""
        cx, cy = door.centre
        nx, ny = door.normal
        half_w = door.width / 2.0
        half_t = self.wall_thickness / 2.0 + 0.06
        if abs(nx) > abs(ny):
            return (cx - half_t, cy - half_w, cx + half_t, cy + half_w)
        return (cx - half_w, cy - half_t, cx + half_w, cy + half_t)


@dataclass(frozen=True)
class RingSpec:
    """Size ranges of a ring building (the procedural family of the simulator's scenarios)."""

    inner_x: tuple[float, float] = (10.0, 13.0)
    """Length of the inner block along x (m)."""
    inner_y: tuple[float, float] = (5.5, 7.0)
    """Depth of the inner block along y (m)."""
    corridor_width: tuple[float, float] = (1.9, 2.3)
    """Corridor width (m)."""
    start_offset: tuple[float, float] = (2.5, 4.0)
    """Distance from the ring's lower-left corner to the start pose (m)."""
    inner_rooms: tuple[int, int] = (2, 3)
    """Number of rooms the inner block is split into."""
    top_rooms: tuple[int, int] = (2, 3)
    """Number of rooms above the top corridor (0 for none)."""
    bottom_rooms: tuple[int, int] = (1, 2)
    """Number of rooms below the bottom corridor (0 for none)."""
    outer_depth: tuple[float, float] = (4.0, 5.5)
    """Depth of the outer rooms (m)."""
    door_width: tuple[float, float] = (1.1, 1.3)
    """Door opening width (m)."""
    wall_thickness: float = 0.2
    """Wall thickness (m)."""


def _split(rng: np.random.Generator, lo: float, hi: float, n: int, wall: float) -> list[tuple]:
    """Split ``[lo, hi]`` into ``n`` spans separated by walls, sizes varying by ±20 %."""
    weights = rng.uniform(0.8, 1.2, size=n)
    free = hi - lo - (n - 1) * wall
    sizes = free * weights / weights.sum()
    spans = []
    x = lo
    for s in sizes:
        spans.append((x, x + s))
        x += s + wall
    return spans


def ring_layout(spec: RingSpec, rng: np.random.Generator) -> Layout:
    """A ring corridor around an inner block of rooms, with rooms above and below it.

    The corridor centreline is a rectangle; its bottom side runs along y = 0 and the start pose
    (0, 0, heading +x) lies on it, ``start_offset`` from its left end. The driving loop goes
    counter-clockwise (right, up, left, down) and back past the start.
    """
    t = spec.wall_thickness
    wc = round(float(rng.uniform(*spec.corridor_width)), 2)
    inner_x = float(rng.uniform(*spec.inner_x))
    inner_y = float(rng.uniform(*spec.inner_y))
    a = float(rng.uniform(*spec.start_offset))
    xl = -a
    xr = xl + inner_x + wc + 2 * t
    ytop = inner_y + wc + 2 * t
    h = wc / 2.0
    corridors = [
        (xl - h, -h, xr + h, h),  # bottom
        (xr - h, -h, xr + h, ytop + h),  # right
        (xl - h, ytop - h, xr + h, ytop + h),  # top
        (xl - h, -h, xl + h, ytop + h),  # left
    ]
    rooms: list[Room] = []

    def door_between(x0: float, x1: float, wall_y: float, ny: float, inset: float) -> Door | None:
        # Doors stay clear of the room's ends and of the ring's corners.
        lo = max(x0 + inset + 1.0, xl + 1.6)
        hi = min(x1 - inset - 1.0, xr - 1.6)
        if hi <= lo:
            return None
        cx = round(float(rng.uniform(lo, hi)), 2)
        return Door((cx, wall_y), (0.0, ny), round(float(rng.uniform(*spec.door_width)), 2))

    # Inner block: rooms side by side, each with a door to the bottom or top corridor.
    bx0, bx1 = xl + h + t, xr - h - t
    by0, by1 = h + t, ytop - h - t
    n_in = int(rng.integers(spec.inner_rooms[0], spec.inner_rooms[1] + 1))
    for x0, x1 in _split(rng, bx0, bx1, n_in, t):
        inset = room_inset((x0, by0, x1, by1))
        if rng.uniform() < 0.5:
            door = door_between(x0, x1, h + t / 2, 1.0, inset)
        else:
            door = door_between(x0, x1, ytop - h - t / 2, -1.0, inset)
        if door is not None:
            rooms.append(Room((x0, by0, x1, by1), door, "inner"))
    # Outer rooms above the top corridor and below the bottom corridor.
    for count, sign in ((spec.top_rooms, 1.0), (spec.bottom_rooms, -1.0)):
        n = int(rng.integers(count[0], count[1] + 1))
        if n == 0:
            continue
        depth = float(rng.uniform(*spec.outer_depth))
        if sign > 0:
            y0, y1 = ytop + h + t, ytop + h + t + depth
            wall_y = ytop + h + t / 2
        else:
            y0, y1 = -h - t - depth, -h - t
            wall_y = -h - t / 2
        for x0, x1 in _split(rng, xl - h, xr + h, n, t):
            rect = (x0, y0, x1, y1)
            door = door_between(x0, x1, wall_y, sign, room_inset(rect))
            if door is not None:
                rooms.append(Room(rect, door, "outer"))
    loop = [(0.0, 0.0), (xr, 0.0), (xr, ytop), (xl, ytop), (xl, 0.0), (0.0, 0.0)]
    layout = Layout(corridors, rooms, t, wc, loop)
    # Doors open onto the bottom (legs 0 and 4) or top (leg 2) corridor.
    for room in rooms:
        cx, cy = room.door.centre
        if cy > ytop / 2:
            layout.loop_doors.append((2, xr - cx, room))
        elif cx >= 0.0:
            layout.loop_doors.append((0, cx, room))
        else:
            layout.loop_doors.append((4, cx - xl, room))
    return layout


def room_inset(rect: Rect) -> float:
    """Distance from a room's walls to the loop the robot drives inside it (m)."""
    w = rect[2] - rect[0]
    d = rect[3] - rect[1]
    return float(np.clip(0.3 * min(w, d), 0.8, 1.2))


def rasterise_layout(
    layout: Layout, frame: GridGeometry
) -> tuple[NDArray[np.uint8], NDArray[np.bool_]]:
    """Labels and interior mask of a layout: free areas carved, walls around them."""
    free = np.zeros(frame.shape, dtype=bool)
    for rect in layout.corridors:
        free[frame.slices(rect)] = True
    for room in layout.rooms:
        free[frame.slices(room.rect)] = True
        free[frame.slices(layout.door_rect(room.door))] = True
    return _walls_around(free, layout.wall_thickness, frame.resolution)


def _walls_around(
    free: NDArray[np.bool_], thickness: float, resolution: float
) -> tuple[NDArray[np.uint8], NDArray[np.bool_]]:
    """Walls of ``thickness`` around the free cells; returns labels and the interior mask."""
    k = max(1, int(round(thickness / resolution)))
    kernel = np.ones((2 * k + 1, 2 * k + 1), np.uint8)
    grown = cv2.dilate(free.astype(np.uint8), kernel) > 0
    labels = np.zeros(free.shape, dtype=np.uint8)
    labels[grown & ~free] = WALL
    return labels, grown


# ------------------------------------------------------------------------------------ clutter


def path_distance(frame: GridGeometry, path_xy: NDArray[np.float64]) -> NDArray[np.float32]:
    """``(H, W)`` distance (m) from each cell centre to the polyline ``path_xy (N, 2)``."""
    mask = np.full(frame.shape, 255, dtype=np.uint8)
    pts = np.round(frame.to_pixels(path_xy) * 16).astype(np.int32)
    cv2.polylines(
        mask, [pts.reshape(-1, 1, 2)], False, 0, thickness=1, lineType=cv2.LINE_8, shift=4
    )
    return cv2.distanceTransform(mask, cv2.DIST_L2, cv2.DIST_MASK_PRECISE) * frame.resolution


def place_clutter(
    rng: np.random.Generator,
    labels: NDArray[np.uint8],
    frame: GridGeometry,
    path_xy: NDArray[np.float64],
    areas: list[tuple[Rect, str]],
    clearance: float = 0.75,
    keep_clear: list[Rect] | None = None,
) -> list[tuple[str, Rect]]:
    """Put furniture boxes and pillars into ``areas`` without coming near the robot's path.

    ``areas`` pairs a free rectangle with its kind (``"room"`` gets tables, cabinets along walls
    and the odd pillar; ``"corridor"`` gets pillars and benches against its walls). A candidate is
    kept only if every cell it covers is free, at least ``clearance`` m from the path and outside
    ``keep_clear`` (door openings). ``labels`` is modified in place; the placed objects are returned.
    """
    dist = path_distance(frame, path_xy)
    blocked = np.zeros(frame.shape, dtype=bool)
    for rect in keep_clear or []:
        blocked[frame.slices(_grow(rect, 0.4))] = True
    placed: list[tuple[str, Rect]] = []
    for rect, kind in areas:
        x0, y0, x1, y1 = rect
        w, d = x1 - x0, y1 - y0
        tries = int(rng.integers(6, 12)) if kind == "room" else max(2, int(max(w, d) / 3.0))
        for _ in range(tries):
            what = rng.uniform()
            if kind == "room" and what < 0.45:  # table or desk, anywhere
                bw, bd = rng.uniform(0.6, 1.6), rng.uniform(0.5, 0.9)
                if rng.uniform() < 0.5:
                    bw, bd = bd, bw
                bx = rng.uniform(x0 + 0.3, max(x0 + 0.31, x1 - 0.3 - bw))
                by = rng.uniform(y0 + 0.3, max(y0 + 0.31, y1 - 0.3 - bd))
                obj = ("furniture", (bx, by, bx + bw, by + bd))
            elif what < 0.8:  # cabinet, shelf or bench against a wall
                length, depth = rng.uniform(0.6, 1.8), rng.uniform(0.3, 0.5)
                obj = ("furniture", _against_wall(rng, rect, length, depth))
            else:  # pillar: round, free-standing or against a wall
                radius = rng.uniform(0.15, 0.25)
                if rng.uniform() < 0.5:
                    px = rng.uniform(x0 + radius, x1 - radius)
                    py = rng.uniform(y0 + radius, y1 - radius)
                else:
                    bx0, by0, bx1, by1 = _against_wall(rng, rect, 2 * radius, 2 * radius)
                    px, py = (bx0 + bx1) / 2, (by0 + by1) / 2
                obj = ("pillar", (px - radius, py - radius, px + radius, py + radius))
            cells = _object_mask(frame, obj)
            if cells is None:
                continue
            rows, cols = cells
            if (
                np.any(labels[rows, cols] != FREE)
                or np.any(blocked[rows, cols])
                or np.min(dist[rows, cols]) < clearance
            ):
                continue
            labels[rows, cols] = FURNITURE if obj[0] == "furniture" else PILLAR
            placed.append(obj)
    return placed


def _grow(rect: Rect, m: float) -> Rect:
    return (rect[0] - m, rect[1] - m, rect[2] + m, rect[3] + m)


def _against_wall(rng: np.random.Generator, rect: Rect, length: float, depth: float) -> Rect:
    """A ``length × depth`` box touching one of the walls of ``rect`` (random wall)."""
    x0, y0, x1, y1 = rect
    side = int(rng.integers(4))
    if side in (0, 1):  # bottom or top wall: length along x
        length = min(length, x1 - x0)
        bx = rng.uniform(x0, x1 - length)
        by = y0 if side == 0 else y1 - depth
        return (bx, by, bx + length, by + depth)
    length = min(length, y1 - y0)
    by = rng.uniform(y0, y1 - length)
    bx = x0 if side == 2 else x1 - depth
    return (bx, by, bx + depth, by + length)


def _object_mask(frame: GridGeometry, obj: tuple[str, Rect]) -> tuple[NDArray, NDArray] | None:
    """Cells (rows, cols) covered by a box or a round pillar; ``None`` if none."""
    kind, rect = obj
    rs, cs = frame.slices(rect)
    rows, cols = np.mgrid[rs, cs]
    if rows.size == 0:
        return None
    if kind == "pillar":
        cx, cy = (rect[0] + rect[2]) / 2, (rect[1] + rect[3]) / 2
        radius = (rect[2] - rect[0]) / 2
        xs = frame.origin[0] + (cols + 0.5) * frame.resolution
        ys = frame.origin[1] + (rows + 0.5) * frame.resolution
        inside = (xs - cx) ** 2 + (ys - cy) ** 2 <= radius**2
        if not np.any(inside):
            return None
        return rows[inside], cols[inside]
    return rows.ravel(), cols.ravel()


# ------------------------------------------------------------------------------------- floor

FLOOR_PALETTES = {
    "corridor_tiles": [(196, 178, 140), (182, 160, 120)],
    "grout": [(128, 116, 96)],
    "planks": [(150, 98, 52), (166, 112, 62), (134, 86, 44), (176, 124, 72)],
    "checker": [(210, 200, 170), (60, 60, 60), (170, 40, 40), (206, 186, 120)],
    "carpet": [(120, 60, 70), (72, 110, 66), (150, 130, 88), (96, 84, 120)],
    "rug": [(190, 80, 40), (220, 170, 60), (40, 120, 110), (150, 40, 70), (230, 210, 160)],
    "patch": [(200, 40, 40), (40, 150, 60), (230, 150, 30), (150, 60, 170), (30, 90, 200)],
    "line": [(240, 200, 20), (220, 90, 20)],
}
"""Floor colours by use; all far from the obstacle colours of :data:`LABEL_COLORS`."""


class FloorPainter:
    """Paints floor materials into a texture grid (vectorised per rectangle)."""

    def __init__(self, frame: GridGeometry, rng: np.random.Generator) -> None:
        self.frame = frame
        self.rng = rng
        self.rgb = np.zeros((*frame.shape, 3), dtype=np.uint8)
        self.rgb[:] = (90, 90, 90)
        self.xs, self.ys = frame.centres()

    def _region(self, rect: Rect) -> tuple[tuple[slice, slice], NDArray, NDArray]:
        rs, cs = self.frame.slices(rect)
        x, y = np.meshgrid(self.xs[cs], self.ys[rs])
        return (rs, cs), x, y

    def _pick(self, name: str) -> tuple[int, int, int]:
        palette = FLOOR_PALETTES[name]
        return palette[int(self.rng.integers(len(palette)))]

    def tiles(self, rect: Rect, size: float, colors: list, grout: float) -> None:
        """Square tiles aligned with the world axes, alternating colours, with grout lines."""
        sl, x, y = self._region(rect)
        ix = np.floor(x / size).astype(np.int64)
        iy = np.floor(y / size).astype(np.int64)
        out = np.asarray(colors, dtype=np.uint8)[(ix + iy) % len(colors)]
        fx = x / size - ix
        fy = y / size - iy
        g = grout / size
        on_grout = (fx < g) | (fy < g)
        out[on_grout] = FLOOR_PALETTES["grout"][0]
        self.rgb[sl] = out

    def planks(self, rect: Rect) -> None:
        """Wooden planks along x or y, colour per plank, staggered joints."""
        sl, x, y = self._region(rect)
        width = float(self.rng.uniform(0.18, 0.25))
        length = float(self.rng.uniform(1.2, 2.0))
        if self.rng.uniform() < 0.5:
            x, y = y, x
        row = np.floor(y / width).astype(np.int64)
        shifted = x / length + 0.37 * row
        col = np.floor(shifted).astype(np.int64)
        palette = np.asarray(FLOOR_PALETTES["planks"], dtype=np.uint8)
        out = palette[(row * 7 + col * 3) % len(palette)]
        joint = ((y / width - row) < 0.06) | ((shifted - col) < 0.012)
        out[joint] = (96, 62, 32)
        self.rgb[sl] = out

    def fill(self, rect: Rect, color: tuple[int, int, int]) -> None:
        """Uniform colour."""
        sl, _, _ = self._region(rect)
        self.rgb[sl] = color

    def rug(self, rect: Rect) -> None:
        """A rectangular rug with a border band and stripes."""
        sl, x, y = self._region(rect)
        colors = self.rng.choice(len(FLOOR_PALETTES["rug"]), size=3, replace=False)
        c = [FLOOR_PALETTES["rug"][int(k)] for k in colors]
        x0, y0, x1, y1 = rect
        border = float(self.rng.uniform(0.12, 0.2))
        edge = np.minimum.reduce([x - x0, x1 - x, y - y0, y1 - y])
        out = np.empty((*x.shape, 3), dtype=np.uint8)
        stripes = np.floor((x - x0) / float(self.rng.uniform(0.25, 0.4))).astype(np.int64) % 2
        out[:] = c[1]
        out[stripes == 1] = c[2]
        out[edge < border] = c[0]
        self.rgb[sl] = out

    def disc(self, centre: tuple[float, float], radius: float, color: tuple[int, int, int]) -> None:
        """A filled circle (coloured patch)."""
        rect = (centre[0] - radius, centre[1] - radius, centre[0] + radius, centre[1] + radius)
        sl, x, y = self._region(rect)
        inside = (x - centre[0]) ** 2 + (y - centre[1]) ** 2 <= radius**2
        region = self.rgb[sl]
        region[inside] = color

    def line(self, a: tuple[float, float], b: tuple[float, float], width: float, color) -> None:
        """A painted straight line segment of ``width`` (m)."""
        x0, x1 = sorted((a[0], b[0]))
        y0, y1 = sorted((a[1], b[1]))
        self.fill((x0 - width / 2, y0 - width / 2, x1 + width / 2, y1 + width / 2), color)


def paint_floor(rng: np.random.Generator, layout: Layout, frame: GridGeometry) -> NDArray[np.uint8]:
    """The floor texture of a layout: tiled corridors with painted lines, a material per room,
    rugs and coloured patches."""
    painter = FloorPainter(frame, rng)
    for rect in layout.corridors:
        painter.tiles(rect, 0.6, FLOOR_PALETTES["corridor_tiles"], grout=0.03)
    h = layout.corridor_width / 2
    line_color = painter._pick("line")
    for a, b in zip(layout.loop[1:-1], layout.loop[2:-1], strict=False):
        _edge_lines(painter, a, b, h, line_color)
    _edge_lines(painter, layout.loop[-2], layout.loop[1], h, line_color)
    for room in layout.rooms:
        x0, y0, x1, y1 = room.rect
        material = int(rng.integers(3))
        if material == 0:
            painter.planks(room.rect)
        elif material == 1:
            colors = rng.choice(len(FLOOR_PALETTES["checker"]), size=2, replace=False)
            painter.tiles(
                room.rect,
                float(rng.uniform(0.45, 0.6)),
                [FLOOR_PALETTES["checker"][int(k)] for k in colors],
                grout=0.0,
            )
        else:
            painter.fill(room.rect, painter._pick("carpet"))
        w, d = x1 - x0, y1 - y0
        if rng.uniform() < 0.8 and w > 2.5 and d > 2.5:
            rw = float(rng.uniform(1.5, min(3.0, w - 1.0)))
            rd = float(rng.uniform(1.2, min(2.2, d - 1.0)))
            rx = float(rng.uniform(x0 + 0.5, x1 - 0.5 - rw))
            ry = float(rng.uniform(y0 + 0.5, y1 - 0.5 - rd))
            painter.rug((rx, ry, rx + rw, ry + rd))
        for _ in range(int(rng.integers(1, 4))):
            r = float(rng.uniform(0.25, 0.6))
            cx = float(rng.uniform(x0 + r, x1 - r))
            cy = float(rng.uniform(y0 + r, y1 - r))
            painter.disc((cx, cy), r, painter._pick("patch"))
    # Coloured patches in the corridors too, so no stretch of corridor looks the same.
    for rect in layout.corridors:
        length = max(rect[2] - rect[0], rect[3] - rect[1])
        for _ in range(int(length / 6.0)):
            r = float(rng.uniform(0.2, 0.4))
            cx = float(rng.uniform(rect[0] + r, rect[2] - r))
            cy = float(rng.uniform(rect[1] + r, rect[3] - r))
            painter.disc((cx, cy), r, painter._pick("patch"))
    return painter.rgb


def _edge_lines(painter: FloorPainter, a, b, h: float, color) -> None:
    """Two painted lines along a corridor leg, 0.35 m in from each wall."""
    off = h - 0.35
    if abs(a[0] - b[0]) > abs(a[1] - b[1]):
        x0, x1 = sorted((a[0], b[0]))
        for s in (-off, off):
            painter.line((x0 + off, a[1] + s), (x1 - off, a[1] + s), 0.05, color)
    else:
        y0, y1 = sorted((a[1], b[1]))
        for s in (-off, off):
            painter.line((a[0] + s, y0 + off), (a[0] + s, y1 - off), 0.05, color)


def floor_mask(
    labels: NDArray[np.uint8], interior: NDArray[np.bool_], frame: GridGeometry, tex: GridGeometry
) -> NDArray[np.bool_]:
    """Texels whose centre lies on a free interior cell of the obstacle grid."""
    xs, ys = tex.centres()
    row, col = frame.cell_of(xs, ys)
    col = np.clip(col, 0, frame.shape[1] - 1)
    row = np.clip(row, 0, frame.shape[0] - 1)
    free = (labels == FREE) & interior
    return free[np.ix_(row, col)]


# --------------------------------------------------------------------------- world assembly


def build_world(
    rng: np.random.Generator,
    layout: Layout,
    path_xy: NDArray[np.float64],
    resolution: float = 0.05,
    texture_resolution: float = 0.02,
    wall_height: float = 2.5,
) -> World:
    """Rasterise a layout, furnish it away from ``path_xy`` and paint its floor."""
    frame = covering(layout.bounds(), resolution, margin=1.0)
    labels, interior = rasterise_layout(layout, frame)
    areas = [(room.rect, "room") for room in layout.rooms]
    areas += [(rect, "corridor") for rect in layout.corridors]
    doors = [layout.door_rect(room.door) for room in layout.rooms]
    placed = place_clutter(rng, labels, frame, path_xy, areas, keep_clear=doors)
    tex = GridGeometry(
        frame.origin,
        texture_resolution,
        (
            math.ceil(frame.shape[0] * resolution / texture_resolution),
            math.ceil(frame.shape[1] * resolution / texture_resolution),
        ),
    )
    texture = paint_floor(rng, layout, tex)
    floor = floor_mask(labels, interior, frame, tex)
    texture[~floor] = (0, 0, 0)
    meta = {
        "corridor_width": layout.corridor_width,
        "rooms": len(layout.rooms),
        "doors": len(layout.rooms),
        "furniture": sum(1 for k, _ in placed if k == "furniture"),
        "pillars": sum(1 for k, _ in placed if k == "pillar"),
    }
    return World(
        labels=labels,
        resolution=resolution,
        origin=frame.origin,
        interior=interior,
        texture=texture,
        texture_resolution=texture_resolution,
        texture_origin=tex.origin,
        floor=floor,
        wall_height=wall_height,
        meta=meta,
    )


def world_around_path(
    rng: np.random.Generator,
    path_xy: NDArray[np.float64],
    corridor_half_width: float = 1.1,
    resolution: float = 0.05,
    texture_resolution: float = 0.02,
    wall_thickness: float = 0.2,
) -> World:
    """A building grown around a given path: free space within ``corridor_half_width`` of it
    (wider halls at a few random places), walls around that, clutter kept clear of the path.

    Any loop the path makes becomes a loop of corridors. Used to simulate a laser along a real
    robot's dead-reckoned path.
    """
    path_xy = np.asarray(path_xy, dtype=np.float64)
    lo = path_xy.min(axis=0)
    hi = path_xy.max(axis=0)
    margin = corridor_half_width + 2.5
    frame = covering((lo[0], lo[1], hi[0], hi[1]), resolution, margin=margin)
    dist = path_distance(frame, path_xy)
    free = dist <= corridor_half_width
    # Halls: wider free discs at a few places along the path.
    n_halls = max(1, int(np.sum(np.hypot(*np.diff(path_xy, axis=0).T)) / 25.0))
    picks = rng.integers(0, len(path_xy), size=n_halls)
    xs, ys = frame.centres()
    for k in picks:
        cx, cy = path_xy[int(k)]
        radius = float(rng.uniform(1.8, 2.6))
        rs, cs = frame.slices((cx - radius, cy - radius, cx + radius, cy + radius))
        gx, gy = np.meshgrid(xs[cs], ys[rs])
        free[rs, cs] |= (gx - cx) ** 2 + (gy - cy) ** 2 <= radius**2
    labels, interior = _walls_around(free, wall_thickness, resolution)
    # Pillars and boxes in the free space, at a clearance from the path.
    candidates = int(np.count_nonzero(free) * resolution**2 / 6.0)
    rows, cols = np.nonzero(free & (dist >= 0.8))
    if rows.size:
        for k in rng.integers(0, rows.size, size=candidates):
            x = frame.origin[0] + (cols[k] + 0.5) * resolution
            y = frame.origin[1] + (rows[k] + 0.5) * resolution
            size = float(rng.uniform(0.2, 0.5))
            obj = (
                "pillar" if rng.uniform() < 0.5 else "furniture",
                (x - size / 2, y - size / 2, x + size / 2, y + size / 2),
            )
            cells = _object_mask(frame, obj)
            if cells is None:
                continue
            r, c = cells
            if np.any(labels[r, c] != FREE) or np.min(dist[r, c]) < 0.6:
                continue
            labels[r, c] = PILLAR if obj[0] == "pillar" else FURNITURE
    tex = GridGeometry(
        frame.origin,
        texture_resolution,
        (
            math.ceil(frame.shape[0] * resolution / texture_resolution),
            math.ceil(frame.shape[1] * resolution / texture_resolution),
        ),
    )
    painter = FloorPainter(tex, rng)
    painter.tiles((-1e9, -1e9, 1e9, 1e9), 0.6, FLOOR_PALETTES["corridor_tiles"], grout=0.03)
    floor = floor_mask(labels, interior, frame, tex)
    texture = painter.rgb
    texture[~floor] = (0, 0, 0)
    return World(
        labels=labels,
        resolution=resolution,
        origin=frame.origin,
        interior=interior,
        texture=texture,
        texture_resolution=texture_resolution,
        texture_origin=tex.origin,
        floor=floor,
        meta={"halls": n_halls},
    )
