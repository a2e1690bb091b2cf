"""The sweep specs shipped in ``tools/sweeps/`` parse, and run what the docs say they run."""

from pathlib import Path

import pytest

from slam.sweep.spec import read_spec_file, spec_from_toml

ROOT = Path(__file__).resolve().parents[1]
SPECS = sorted((ROOT / "tools/sweeps").glob("*.toml"))
BENCH_LOGS = ("intel", "aces", "fr079", "mit-csail", "fr-clinic", "mit-killian")


def load(name: str):
    path = ROOT / "tools/sweeps" / name
    return spec_from_toml(read_spec_file(path), path)


@pytest.mark.parametrize("path", SPECS, ids=lambda p: p.name)
def test_every_shipped_spec_parses_into_cells(path):
    spec = spec_from_toml(read_spec_file(path), path)
    cells = spec.cells()
    assert cells, f"{path.name}: no cells"
    assert len({c.name for c in cells}) == len(cells)


def test_the_bench_spec_runs_the_six_logs_on_seeds_0_to_3_one_at_a_time():
    spec = load("slam_bench.toml")
    assert spec.logs == BENCH_LOGS
    assert spec.seeds == (0, 1, 2, 3)
    assert spec.workers == 1
    assert spec.metric_of("mit-killian") == "auto"  # its re-timed relations


def test_the_more_seeds_spec_runs_the_six_logs_on_seeds_4_to_11_with_the_defaults():
    spec = load("more_seeds.toml")
    assert spec.logs == BENCH_LOGS
    assert spec.seeds == tuple(range(4, 12))
    assert [s.overrides for s in spec.settings] == [()]
    assert spec.metric_of("mit-killian") == "auto"
    assert len(spec.cells()) == 6 * 8


def test_the_short_range_spec_runs_the_six_logs_with_an_8_m_laser():
    spec = load("short_range.toml")
    assert spec.logs == BENCH_LOGS
    assert spec.seeds == (0, 1)
    assert [s.overrides for s in spec.settings] == [("lidar.range_max=8",)]
    assert len(spec.cells()) == 6 * 2


def test_the_scan_rate_spec_runs_the_six_logs_at_a_half_and_a_third_of_their_rate():
    spec = load("scan_rate.toml")
    assert spec.logs == BENCH_LOGS
    assert spec.seeds == (0, 1)
    assert [s.overrides for s in spec.settings] == [("filter.every=2",), ("filter.every=3",)]
    assert spec.metric_of("mit-killian") == "auto"
    assert len(spec.cells()) == 6 * 2 * 2
