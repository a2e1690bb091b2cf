"""The vacancy grid (:class:`slam.mapping.VacancyGrid`, :mod:`slam.kernels.vacancy`): which hits
later rays went through, and the matcher that leaves them out.

The rules, one test each: a hit is seen through after ``after`` steep rays that end well beyond
it; a ray grazing the hit's surface, or ending near it, does not count; a new return brings it
back; a live hit in the window keeps its neighbours; a grid that grows keeps what it holds where
it was. Then the case it is for: a thing that moved on along a corridor pulls the match back to
where it stood, unless its old hits are vacated.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from slam.config import Config
from slam.mapping import ParticleMaps, VacancyGrid, likelihood_tables
from slam.particle_filter import vacancy_grid

ORIGIN = np.zeros(2)


def _grid(after: int = 2) -> VacancyGrid:
    """A 0.1 m vacancy grid around the origin, rays counted up to 0.3 m short of their ends."""
    return VacancyGrid(0.1, (0.0, 0.0), after, 0.3, size_m=30.0, grow_margin_m=5.0)


def _hit(grid: VacancyGrid, xy: tuple[float, float], normal: float) -> None:
    """One return at world ``xy`` (surface normal at angle ``normal``), seen from the origin."""
    p = np.array([xy])
    grid.observe(ORIGIN, p, p, np.array([normal]))


def _through(grid: VacancyGrid, end: tuple[float, float]) -> None:
    """One reading past the laser's range from the origin to ``end``: a ray with no return."""
    grid.observe(ORIGIN, np.array([end]), np.zeros((0, 2)), np.zeros(0))


def _state(grid: VacancyGrid, xy: tuple[float, float]) -> tuple[int, int]:
    """``(state, vacated)`` of the cell holding world ``xy``."""
    ix, iy = grid.geometry.world_to_cell(np.array([xy]))[0]
    return int(grid.layers[0, iy, ix]), int(grid.layers[3, iy, ix])


def test_a_hit_is_seen_through_after_the_set_number_of_steep_rays() -> None:
    grid = _grid(after=2)
    _hit(grid, (5.05, 0.05), np.pi)  # a surface facing the sensor
    assert _state(grid, (5.05, 0.05)) == (1, 0)
    _through(grid, (9.0, 0.05))
    assert _state(grid, (5.05, 0.05)) == (1, 0)  # one ray: not yet
    _through(grid, (9.0, 0.05))
    assert _state(grid, (5.05, 0.05)) == (2, 1)
    # the window (one cell to each side) around it is vacated too, and nothing beyond it
    assert _state(grid, (5.15, 0.15))[1] == 1
    assert _state(grid, (5.25, 0.05))[1] == 0


def test_a_grazing_ray_or_one_that_ends_near_the_hit_does_not_count() -> None:
    grid = _grid(after=1)
    _hit(grid, (5.05, 0.05), np.pi / 2)  # a wall along the ray: the ray grazes it
    for _ in range(5):
        _through(grid, (9.0, 0.05))
    assert _state(grid, (5.05, 0.05)) == (1, 0)
    _hit(grid, (3.05, 2.05), np.pi + np.arctan2(2.05, 3.05))  # facing the sensor
    # a ray 0.25 m beyond it: it stops counting 0.3 m + 2 % of its 3.9 m short of its end,
    # before it enters the hit's cell
    far = np.array([3.05, 2.05]) * (1.0 + 0.25 / np.hypot(3.05, 2.05))
    for _ in range(5):
        _through(grid, tuple(far))
    assert _state(grid, (3.05, 2.05)) == (1, 0)
    # one that ends a metre beyond it counts
    _through(grid, tuple(np.array([3.05, 2.05]) * (1.0 + 1.0 / np.hypot(3.05, 2.05))))
    assert _state(grid, (3.05, 2.05)) == (2, 1)


def test_a_new_return_brings_a_hit_back_and_a_live_neighbour_keeps_the_window() -> None:
    grid = _grid(after=1)
    _hit(grid, (5.05, 0.05), np.pi)
    _through(grid, (9.0, 0.05))
    assert _state(grid, (5.05, 0.05)) == (2, 1)
    _hit(grid, (5.07, 0.08), np.pi)  # the same cell again: something stands there now
    assert _state(grid, (5.05, 0.05)) == (1, 0)
    _through(grid, (9.0, 0.05))
    _hit(grid, (5.15, 0.05), np.pi)  # a live hit in the next cell
    assert _state(grid, (5.05, 0.05)) == (2, 0)  # seen through, but not vacated


def test_the_vacancy_grid_grows_to_hold_what_it_observes() -> None:
    grid = _grid()
    before = grid.layers.shape
    _hit(grid, (40.0, -35.0), 0.0)
    assert grid.layers.shape[1] > before[1] and grid.layers.shape[2] > before[2]
    assert _state(grid, (40.0, -35.0)) == (1, 0)
    assert grid.memory_bytes() == grid.layers.size


def test_growing_keeps_what_the_grid_holds_where_it_was() -> None:
    """A grid that grows to the left and below (its origin moves) keeps every cell's content at
    the same world position, and rays after the growth count on the old hits."""
    grid = _grid(after=1)
    _hit(grid, (5.05, 0.05), np.pi)  # seen through below: gone, its window vacated
    _through(grid, (9.0, 0.05))
    _hit(grid, (0.05, 4.05), -np.pi / 2)  # live, facing the sensor
    _hit(grid, (-4.05, -0.05), 0.0)  # live: seen through once after the growth
    before = grid.layers.copy()
    origin = grid.origin.copy()
    _hit(grid, (-40.0, -35.0), 0.0)  # far to the left and below
    shift = np.round((origin - grid.origin) / grid.resolution).astype(int)
    assert shift[0] > 0 and shift[1] > 0
    rows, cols = before.shape[1:]
    kept = grid.layers[:, shift[1] : shift[1] + rows, shift[0] : shift[0] + cols]
    assert np.array_equal(kept, before)
    assert _state(grid, (5.05, 0.05)) == (2, 1) and _state(grid, (5.15, 0.15))[1] == 1
    assert _state(grid, (0.05, 4.05)) == (1, 0)
    _through(grid, (-9.0, -0.05))
    assert _state(grid, (-4.05, -0.05)) == (2, 1)
    assert _state(grid, (0.05, 4.05)) == (1, 0)


def _corridor_maps() -> tuple[ParticleMaps, Config]:
    """One particle's map of a corridor (walls at y = ±1.5 from x = −3 to 9: nothing along x
    but what stands in it) with something standing across it at x = 3."""
    config = Config()
    rc = config.rbpf
    maps = ParticleMaps(1, config.map.resolution, rc.dmax, size_m=30.0)
    xs = np.arange(-3.0, 9.0, 0.05)
    ys = np.arange(-0.3, 0.3, 0.05)
    hx = np.concatenate([xs, xs, np.full(ys.size, 3.0)])
    hy = np.concatenate([np.full(xs.size, 1.5), np.full(xs.size, -1.5), ys])
    maps.insert(np.zeros((1, 3)), hx, hy, hx, hy, rc.skip_insert_below)
    return maps, config


def _scan_at(x: float, thing_x: float) -> tuple[np.ndarray, np.ndarray]:
    """Robot-frame returns of the robot at ``(x, 0, 0)``: the walls from 1 to 5 m ahead and the
    thing, now at ``thing_x``."""
    xs = np.arange(x + 1.0, x + 5.0, 0.1)
    ys = np.arange(-0.3, 0.3, 0.05)
    ex = np.concatenate([xs, xs, np.full(ys.size, thing_x)]) - x
    ey = np.concatenate([np.full(xs.size, 1.5), np.full(xs.size, -1.5), ys])
    return ex, ey


@pytest.mark.parametrize("vacate", [False, True])
def test_a_thing_that_moved_on_pulls_the_match_back_unless_its_hits_are_vacated(
    vacate: bool,
) -> None:
    maps, config = _corridor_maps()
    rc = config.rbpf
    luts = likelihood_tables(np.asarray(rc.sigmas), rc.z_hit, rc.z_rand, rc.dmax)
    grid = VacancyGrid(0.1, (0.0, 0.0), 2, rc.dmax, size_m=30.0, grow_margin_m=5.0)
    ys = np.arange(-0.3, 0.3, 0.05)
    things = np.c_[np.full(ys.size, 3.0), ys]
    grid.observe(ORIGIN, things, things, np.full(ys.size, np.pi))
    # two scans since, from the start, saw through where the thing stood, to 8 m
    for _ in range(2):
        grid.observe(ORIGIN, things * (8.0 / 3.0), np.zeros((0, 2)), np.zeros(0))
    # the robot moved 0.2 m, and the thing 0.2 m too
    ex, ey = _scan_at(0.2, 3.2)
    match = maps.match(
        np.array([[0.2, 0.0, 0.0]]), ex, ey, luts, rc.max_iterations, rc.tolerance,
        rc.min_inliers, rc.coarse_stride, vacancy=grid.view() if vacate else None,
    )  # fmt: skip
    x = float(match.poses[0, 0])
    if vacate:
        assert abs(x - 0.2) < 0.01  # the walls alone: nothing moves it along the corridor
    else:
        assert x < 0.05  # pulled back to where the thing's old hits fit
    # the thing's returns lie in known space either way: they count among the inliers
    assert match.inliers[0] == pytest.approx(1.0)


def test_the_filter_keeps_a_vacancy_grid_only_with_vacate_after() -> None:
    config = Config()
    assert config.rbpf.vacate_after == 0  # off by default (docs/accuracy.md)
    assert vacancy_grid(config, np.zeros(3), 0.05) is None
    on = dataclasses.replace(config, rbpf=dataclasses.replace(config.rbpf, vacate_after=2))
    grid = vacancy_grid(on, np.zeros(3), 0.05)
    assert grid is not None and grid.resolution == pytest.approx(0.1) and grid.after == 2
    assert grid.margin == config.rbpf.dmax
