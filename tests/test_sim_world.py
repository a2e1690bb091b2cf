"""Simulator worlds, ray casting and trajectories: geometry with numbers, loops, clearances."""

import math

import cv2
import numpy as np
import pytest

from slam.sim.kernels import cast_scans, first_hit
from slam.sim.scenarios import ROBOT_RADIUS, SCENARIOS, generate_scene
from slam.sim.trajectory import DriveLimits, drive, fillet_path
from slam.sim.world import (
    FLOOR_PALETTES,
    FREE,
    LABEL_COLORS,
    WALL,
    path_distance,
    world_around_path,
)


@pytest.fixture(scope="module")
def demo_scene():
    return generate_scene(SCENARIOS["demo"], np.random.default_rng(20), t0=0.0)


# ------------------------------------------------------------------------------ ray casting


def _box_grid():
    """10 x 10 m at 0.05 m, origin (0, 0), a wall column at x in [6, 6.05) and y in [0, 10)."""
    labels = np.zeros((200, 200), np.uint8)
    labels[:, 120] = WALL
    return labels


def test_first_hit_distances_are_exact():
    labels = _box_grid()
    # From (1.0, 5.0) along +x: the wall face at x = 6.0 is 5.0 m away = 100 cells.
    d, side, lab = first_hit(labels, 20.0, 100.0, 1.0, 0.0, 1e9)
    assert d == pytest.approx(100.0, abs=1e-9) and side == 0 and lab == WALL
    # At 60 degrees: 5 m / cos(60) = 10 m = 200 cells.
    a = math.radians(60.0)
    d, side, _ = first_hit(labels, 20.0, 20.0, math.cos(a), math.sin(a), 1e9)
    assert d == pytest.approx(200.0, abs=1e-9) and side == 0
    # Away from the wall: leaves the grid, no hit.
    d, side, lab = first_hit(labels, 20.0, 100.0, -1.0, 0.0, 1e9)
    assert math.isinf(d) and lab == 0
    # Beyond max distance: no hit.
    d, _, _ = first_hit(labels, 20.0, 100.0, 1.0, 0.0, 99.0)
    assert math.isinf(d)
    # Starting inside the wall.
    d, side, lab = first_hit(labels, 120.5, 100.0, 1.0, 0.0, 1e9)
    assert d == 0.0 and side == -1 and lab == WALL


def test_cast_scans_matches_geometry_for_every_beam():
    labels = _box_grid()
    angles = np.linspace(-1.2, 1.2, 241)
    poses = np.array([[1.0, 5.0, 0.0], [2.0, 4.0, 0.3]])
    ranges, incidence = cast_scans(labels, 0.0, 0.0, 0.05, poses, angles, 30.0)
    for k, (x, _y, th) in enumerate(poses):
        expected = (6.0 - x) / np.cos(th + angles)
        inside = (poses[k, 1] + expected * np.sin(th + angles) >= 0) & (
            poses[k, 1] + expected * np.sin(th + angles) < 10
        )
        np.testing.assert_allclose(ranges[k][inside], expected[inside], atol=1e-9)
        np.testing.assert_allclose(
            incidence[k][inside], np.abs(np.cos(th + angles))[inside], atol=1e-6
        )
        assert np.all(np.isinf(ranges[k][~inside]))


# ------------------------------------------------------------------------------------ paths


def test_fillet_rounds_a_right_angle_with_the_requested_radius():
    pts, curv = fillet_path(np.array([[0.0, 0.0], [5.0, 0.0], [5.0, 5.0]]), np.array([0, 1.0, 0]))
    steps = np.hypot(*np.diff(pts, axis=0).T)
    assert steps.max() <= 0.0201
    length = steps.sum()
    # Two 4 m straights plus a quarter circle of radius 1.
    assert length == pytest.approx(8.0 + math.pi / 2, abs=1e-3)
    assert curv.max() == pytest.approx(1.0) and curv.min() == 0.0
    np.testing.assert_allclose(pts[0], [0, 0]) and np.testing.assert_allclose(pts[-1], [5, 5])
    # The corner is cut by r (sqrt(2) - 1) = 0.414 m.
    corner = np.hypot(pts[:, 0] - 5.0, pts[:, 1]).min()
    assert corner == pytest.approx(math.sqrt(2) - 1, abs=0.01)


def test_drive_respects_the_robot_limits_and_is_exact_between_steps():
    limits = DriveLimits()
    waypoints = np.array([[0, 0], [6, 0], [6, 4], [0, 4], [0, 1]], float)
    traj, info = drive(waypoints, np.array([0, 1.0, 1.0, 1.0, 0]), 40.0, 100.0, limits)
    assert info["completed"]
    assert limits.cruise_min <= info["cruise_speed"] <= limits.cruise_max
    assert traj.v.min() >= 0.0 and traj.v.max() <= limits.cruise_max + 1e-9
    assert np.abs(traj.omega).max() <= limits.max_omega + 1e-9
    assert np.abs(np.diff(traj.omega)).max() / traj.dt <= limits.max_alpha + 1e-6
    assert np.diff(traj.v).max() / traj.dt <= limits.accel + 1e-6
    # Stands still at the origin during the start pause.
    start = traj.pose_at(np.array([99.0, 100.0, 100.5]))
    np.testing.assert_allclose(start, 0.0, atol=1e-12)
    # Queries at step boundaries return the stored poses; between them, exact arcs.
    k = np.array([1500, 20000, 33333])
    np.testing.assert_allclose(
        traj.pose_at(100.0 + k * traj.dt, unwrap=True), traj.poses[k], atol=1e-9
    )
    mid = traj.pose_at(np.array([100.0 + 20000.5 * traj.dt]), unwrap=True)[0]
    v, w, p = traj.v[20000], traj.omega[20000], traj.poses[20000]
    tau = 0.5 * traj.dt
    chord = v * tau * np.sinc(w * tau / 2 / np.pi)
    assert mid[0] == pytest.approx(p[0] + chord * math.cos(p[2] + w * tau / 2), abs=1e-12)
    assert info["max_tracking_error_m"] < 0.15


# ------------------------------------------------------------------------------ demo world


def test_demo_route_visits_rooms_closes_the_loop_at_realistic_speeds(demo_scene):
    info = demo_scene.info
    traj = demo_scene.trajectory
    assert info["completed"] and info["rooms_visited"] >= 2
    assert 0.5 <= info["cruise_speed"] <= 1.0
    assert 60.0 <= info["driven_length_m"] <= 124.0
    assert 0.4 <= info["max_turn_rate"] <= 1.2
    # Starts at (0, 0, 0); the last stretch drives over the start again (loop closure).
    np.testing.assert_allclose(traj.poses[0], 0.0)
    late = traj.poses[len(traj.poses) * 3 // 4 :, :2]
    assert np.hypot(late[:, 0], late[:, 1]).min() < 0.1
    far = np.hypot(traj.poses[:, 0], traj.poses[:, 1]).max()
    assert far > 10.0  # it went around the building, not in place


@pytest.mark.parametrize("duration", [90.0, 100.0])
def test_a_log_longer_than_the_scenario_drives_the_route_lap_after_lap(duration):
    """``small`` is planned for 45 s; a longer log drives its route lap after lap at the same
    speed, through the start after each lap, never parked (twice the nominal duration included:
    a lap takes less than the nominal log, which starts and ends at rest), clear of the walls."""
    nominal = generate_scene(SCENARIOS["small"], np.random.default_rng(5))
    long = generate_scene(SCENARIOS["small"], np.random.default_rng(5), duration=duration)
    assert long.info["cruise_speed"] == nominal.info["cruise_speed"]
    overlap = float(np.hypot(*nominal.route.waypoints[-1]))  # the drive past the start
    lap = nominal.info["route_length_m"] - overlap
    laps = (long.info["route_length_m"] - overlap) / lap
    assert laps == pytest.approx(round(laps), abs=1e-6) and round(laps) >= 3
    assert not long.info["completed"]  # cut where the log ends, not parked at the end
    traj = long.trajectory
    assert traj.duration == pytest.approx(duration)
    # the first lap is the nominal log's drive (to the last bits of the arc lengths' sums)
    steps = len(nominal.trajectory.v) - int(8.0 / traj.dt)  # before the nominal drive brakes
    np.testing.assert_allclose(traj.poses[:steps], nominal.trajectory.poses[:steps], atol=1e-4)
    assert np.all(traj.v[-int(10.0 / traj.dt) :] > 0.2)  # still driving in the last 10 s
    at_start = np.hypot(traj.poses[:, 0], traj.poses[:, 1]) < 0.1
    passes = np.count_nonzero(np.diff(at_start.astype(np.int8)) == 1)
    assert passes == 2  # the start is left at rest, then driven through after laps 1 and 2
    ratio = duration / SCENARIOS["small"].duration  # 2 or 2.2 nominal logs' drives, at least
    assert long.info["driven_length_m"] > (ratio - 0.05) * nominal.info["driven_length_m"]
    assert long.info["max_tracking_error_m"] == pytest.approx(
        nominal.info["max_tracking_error_m"], abs=0.005
    )
    assert long.info["clearance_m"] >= ROBOT_RADIUS


def test_demo_world_keeps_the_robot_clear_and_has_a_loop(demo_scene):
    world = demo_scene.world
    assert demo_scene.info["clearance_m"] >= ROBOT_RADIUS
    # The start cell is free, and the building is closed: every free cell is inside.
    row, col = world.cell_of(0.0, 0.0)
    assert world.labels[row, col] == FREE
    assert np.all(world.interior[_reachable(world)])
    # A loop: the obstacles inside the ring corridor are not connected to the outer walls.
    blocked = (world.labels != FREE).astype(np.uint8)
    n, _ = cv2.connectedComponents(blocked, connectivity=4)
    assert n - 1 >= 2
    meta = world.meta
    assert meta["rooms"] >= 4 and meta["furniture"] >= 5 and meta["pillars"] >= 1


def _reachable(world):
    """Free cells connected to the start cell."""
    free = (world.labels == FREE).astype(np.uint8)
    _, comp = cv2.connectedComponents(free, connectivity=4)
    row, col = world.cell_of(0.0, 0.0)
    return comp == comp[row, col]


def test_demo_world_is_closed_no_beam_escapes(demo_scene):
    world = demo_scene.world
    reach = _reachable(world)
    rows, cols = np.nonzero(reach)
    pick = np.random.default_rng(0).integers(0, rows.size, 200)
    xs = world.origin[0] + (cols[pick] + 0.5) * world.resolution
    ys = world.origin[1] + (rows[pick] + 0.5) * world.resolution
    poses = np.stack([xs, ys, np.zeros_like(xs)], axis=1)
    ranges, _ = cast_scans(
        world.labels, *world.origin, world.resolution, poses, np.linspace(-np.pi, np.pi, 360), 100.0
    )
    assert np.isfinite(ranges).all()


def test_floor_texture_has_structure_and_walls_stand_out(demo_scene):
    world = demo_scene.world
    floor_colors = world.texture[world.floor]
    distinct = np.unique(floor_colors, axis=0)
    assert len(distinct) >= 12  # tiles, grout, lines, planks, rugs, patches
    assert world.floor.mean() > 0.3
    # Obstacle colours (and their darker faces) are far from every floor colour.
    palette = np.array([c for colors in FLOOR_PALETTES.values() for c in colors], float)
    for color in LABEL_COLORS[1:]:
        for shade in (1.0, 0.82):
            dist = np.abs(palette - color * shade).max(axis=1).min()
            assert dist >= 30, (color, shade)
    # Texture and map share the origin convention: the start lies on a visible floor texel.
    r, c = world.texel_of(0.0, 0.0)
    assert world.floor[r, c]


def test_same_seed_same_world_other_seed_other_world():
    a = generate_scene(SCENARIOS["small"], np.random.default_rng(5))
    b = generate_scene(SCENARIOS["small"], np.random.default_rng(5))
    c = generate_scene(SCENARIOS["small"], np.random.default_rng(6))
    assert np.array_equal(a.world.labels, b.world.labels)
    assert np.array_equal(a.world.texture, b.world.texture)
    assert np.array_equal(a.trajectory.poses, b.trajectory.poses)
    assert (
        not np.array_equal(a.world.texture, c.world.texture)
        or a.world.labels.shape != c.world.labels.shape
    )


def test_building_grown_around_a_looping_path():
    t = np.linspace(0, 2 * np.pi, 400)
    path = np.stack([8 * np.cos(t), 5 * np.sin(t)], axis=1)
    world = world_around_path(np.random.default_rng(0), path)
    frame = world.geometry
    # The path stays at least 0.6 m from every obstacle cell centre.
    dist = world.obstacle_distance()
    rows, cols = world.cell_of(path[:, 0], path[:, 1])
    assert dist[rows, cols].min() >= 0.6
    # Walls exist near the path (within 3 m) and the ellipse encloses an island of walls.
    near = path_distance(frame, path) < 3.0
    assert np.any(world.labels[near] == WALL)
    centre_row, centre_col = world.cell_of(0.0, 0.0)
    assert (
        world.labels[centre_row, centre_col] == FREE and not world.interior[centre_row, centre_col]
    )
