"""The sweep specs shipped in ``tools/sweeps/`` and those of ``docs/sweep.md`` parse and their
cells' configurations load (checked as ``slam sweep`` checks them, no cell run), and the shipped
ones run what the docs say they run."""

import re
from pathlib import Path

import pytest

from slam.cli import build_parser
from slam.sweep.driver import check_sweep
from slam.sweep.spec import build_spec, read_spec_file, spec_from_toml
from slam.sweep.tune import parse_tune, tune_spec_for

ROOT = Path(__file__).resolve().parents[1]
SPECS = sorted((ROOT / "tools/sweeps").glob("*.toml"))
DOC = ROOT / "docs/sweep.md"
BENCH_LOGS = ("intel", "aces", "fr079", "mit-csail", "fr-clinic", "mit-killian")


def load(name: str):
    path = ROOT / "tools/sweeps" / name
    return spec_from_toml(read_spec_file(path), path)


@pytest.mark.parametrize("path", SPECS, ids=lambda p: p.name)
def test_every_shipped_spec_parses_into_cells(path, tmp_path):
    spec = spec_from_toml(read_spec_file(path), path)
    cells = spec.cells()
    assert cells, f"{path.name}: no cells"
    assert len({c.name for c in cells}) == len(cells)
    assert set(check_sweep(spec, tmp_path)) == {c.name for c in cells}  # every config loads


def doc_examples() -> list[str]:
    """The TOML blocks of docs/sweep.md: the spec file's layout, then the tune spec."""
    return re.findall(r"^```toml\n(.*?)^```$", DOC.read_text(), flags=re.MULTILINE | re.DOTALL)


def checked(text: str, folder: Path, command: str) -> tuple[object, dict[str, str]]:
    """The spec ``text`` as ``slam COMMAND SPEC.toml`` builds it, and its cells' config.toml
    texts (checked as the sweep checks them before any cell runs; none runs)."""
    path = folder / "example.toml"
    path.write_text(text)
    (folder / "my_robot.toml").write_text("[lidar]\nrange_max = 30.0\n")  # its `config`
    args = build_parser().parse_args([command, str(path)])
    spec = build_spec(path, args)
    if command == "tune":
        spec = tune_spec_for(spec, parse_tune(read_spec_file(path), str(path), args))
    return spec, check_sweep(spec, folder / "data")


def test_the_docs_spec_example_is_a_valid_sweep(tmp_path):
    spec, configs = checked(doc_examples()[0], tmp_path, "sweep")
    assert spec.logs == ("intel", "aces", "mit-killian")
    assert spec.metric_of("mit-killian") == "quality"
    names = [s.name for s in spec.settings]
    assert names[:2] == ["temperature=10,enabled=true", "temperature=10,enabled=false"]
    assert len(configs) == 3 * 4 * 6
    text = configs["aces-seed3-temperature=40,enabled=false"]
    assert "\n[loops]\nenabled = false\n" in text and "\ntemperature = 40.0\n" in text
    assert "\nrange_max = 30.0\n" in text and "\nresolution = 0.05\n" in text


def test_the_docs_tune_example_is_a_valid_tune(tmp_path):
    spec, configs = checked(doc_examples()[1], tmp_path, "tune")
    assert len(spec.settings) == 12 and len(configs) == 12 * 2 * 2
    keys = {key for setting in spec.settings for key, _value in setting.values}
    assert keys == {"rbpf.temperature", "filter.particles", "loops.enabled"}


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
