"""GridGeometry, the kernels' cell rule and the one 3x3 solver."""

from __future__ import annotations

import numpy as np
import pytest

from slam.config import LoopConfig
from slam.errors import ConfigError
from slam.grid_geometry import GridGeometry, covering
from slam.kernels.cells import cell_index
from slam.kernels.linalg import solve_sym3


def test_world_to_cell_follows_the_lower_left_corner_rule():
    g = GridGeometry((-1.0, 2.0), 0.25, (40, 60))
    cells = g.world_to_cell(np.array([[-1.0, 2.0], [-0.76, 2.24], [-0.75, 2.25], [-1.001, 1.5]]))
    assert cells.tolist() == [[0, 0], [0, 0], [1, 1], [-1, -2]]
    row, col = g.cell_of(np.array([13.99]), np.array([11.99]))
    assert (int(row[0]), int(col[0])) == (39, 59) and g.inside(row, col).all()
    assert not g.inside(np.array([40]), np.array([0])).any()
    assert g.extent == (-1.0, 2.0, 14.0, 12.0)
    # picture rows count down from the top: the cell row 0 is the last picture row
    assert g.world_to_pixel(np.array([-0.9, 2.1])).tolist() == [0, 39]
    # the rule divides: (2.05 - 2.0) / 0.05 is just below 1, so 2.05 is still in cell 0
    assert GridGeometry((0.0, 2.0), 0.05, (1, 1)).world_to_cell([0.0, 2.05]).tolist() == [0, 0]


def test_the_array_rule_and_the_kernel_rule_agree_to_the_bit():
    rng = np.random.default_rng(3)
    g = GridGeometry((-7.3, 4.15), 0.05, (100, 100))
    xy = rng.uniform(-10.0, 10.0, (2000, 2))
    # points on cell borders, where rounding decides
    xy[:500] = g.origin + np.round((xy[:500] - g.origin) / 0.05) * 0.05
    cells = g.world_to_cell(xy)
    for (x, y), (ix, iy) in zip(xy, cells, strict=True):
        assert cell_index(x, g.origin[0], 0.05) == ix and cell_index(y, g.origin[1], 0.05) == iy


def test_covering_puts_the_origin_on_a_multiple_of_the_resolution():
    g = covering((0.03, -1.12, 2.0, 1.0), 0.1, 0.5)
    assert g.origin == (-0.5, -1.7) and g.shape == (32, 30)
    rows, cols = g.slices((0.0, 0.0, 1.0, 1.0))
    assert (rows.start, rows.stop, cols.start, cols.stop) == (17, 27, 5, 15)


def test_solve_sym3_solves_symmetric_systems_and_refuses_singular_ones():
    rng = np.random.default_rng(0)
    for _ in range(50):
        m = rng.normal(size=(3, 3))
        h = m @ m.T + 0.1 * np.eye(3)
        g = rng.normal(size=3)
        *x, ok = solve_sym3(h[0, 0], h[0, 1], h[0, 2], h[1, 1], h[1, 2], h[2, 2], *g, 1e-18)
        assert ok
        np.testing.assert_allclose(h @ np.array(x), g, atol=1e-9)
    assert solve_sym3(1.0, 1.0, 0.0, 1.0, 0.0, 1.0, 1.0, 2.0, 3.0, 1e-18) == (0.0, 0.0, 0.0, False)


def test_loop_numbers_are_bounded_config_fields():
    c = LoopConfig()
    assert (c.submap_size, c.submap_grow_margin, c.submap_tiles) == (20.0, 10.0, 1024)
    assert (c.search_beams, c.match_iteration_factor) == (60, 2)
    assert (c.converged_xy, c.converged_th, c.solver_tolerance) == (1e-3, 1e-4, 1e-8)
    with pytest.raises(ConfigError, match="search_beams"):
        LoopConfig(search_beams=0)
    with pytest.raises(ConfigError, match="submap_tiles"):
        LoopConfig(submap_tiles=10**7)
