"""The bench tables and figures of README.md, docs/localize.md and docs/evaluation.md agree with
docs/bench/*.json (tools/readme_tables.py).

The first tests fail when someone edits a figure by hand or re-runs a bench without regenerating
the README (fix: ``uv run python tools/readme_tables.py``); the claims the README's prose makes
about those figures are checked against the JSON too. The rest test the generator itself on
copies of the JSON: stale parts named, a missing key one line and exit 2, an extended slam.json
(per-seed figures, median, share > 0.2 m, more logs) and a texture.json filled in.
"""

from __future__ import annotations

import copy
import json
import re
from pathlib import Path

import pytest
from tool_modules import load_tool

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"
BENCH = ROOT / "docs" / "bench"

tables = load_tool("readme_tables")


def slam_benches() -> dict:
    """The benches of docs/bench/slam.json."""
    return json.loads((BENCH / "slam.json").read_text())["benches"]


def section_of(text: str, title: str) -> str:
    """The ``## title`` section of a README text."""
    (body,) = re.findall(rf"^## {title}\n(.*?)(?=^## )", text, flags=re.M | re.S)
    return body


def section(title: str) -> str:
    """The README's ``## title`` section."""
    return section_of(README.read_text(), title)


def write_bench(folder: Path, name: str, benches: dict) -> None:
    """A docs/bench-style JSON file in ``folder``."""
    (folder / f"{name}.json").write_text(json.dumps({"machine": {}, "benches": benches}))


def test_pages_match_bench_json(capsys):
    assert tables.main(["--check"]) == 0, capsys.readouterr().out


def test_every_table_of_the_bench_sections_is_generated():
    for title in ("Accuracy", "Performance"):
        body = section(title)
        outside = re.sub(r"<!-- table:[\w.-]+ -->\n.*?<!-- /table -->", "", body, flags=re.S)
        assert "|" not in outside, f"a hand-written table in README section {title}"
        assert "<!-- table:" in body


def test_readme_tables_show_the_json_figures():
    benches = slam_benches()
    accuracy, performance = section("Accuracy"), section("Performance")
    intel = benches["slam.intel"]["rbpf"]
    assert f"| intel | **slam rbpf** | **{tables.fixed(intel['trans_mean'], 3)} ± " in accuracy
    assert "| fr079 | GMapping, published / measured here | 0.061 / diverges | | |" in accuracy
    classic = benches["slam.demo_classic_100"]
    assert f"| demo, classic, 100 particles | {tables.fixed(classic['wall_s'], 1)} |" in performance
    assert "| fr079 (4 934 scans), rbpf, 30 particles |" in performance  # its FLASER lines


def test_the_parts_table_shows_each_runs_parts_and_their_sum():
    """The Performance section's time by part: the JSON's ``estimate_parts_s`` of seed 0, one
    column per part (the filter first), the sum last; a bench without them is named."""
    benches = slam_benches()
    performance = section("Performance")
    intel = benches["slam.intel"]["rbpf"]["estimate_parts_s"]
    assert list(intel)[0] == "filter"
    cells = " | ".join(tables.fixed(v, 2) for v in intel.values())
    assert f"| intel | {cells} | {tables.fixed(sum(intel.values()), 1)} |" in performance
    assert "| run | filter | loop closing |" in performance
    killian = benches["slam.mit-killian"]["rbpf"]["estimate_parts_s"]
    assert f"| mit-killian | {tables.fixed(killian['filter'], 2)} |" in performance
    broken = json.loads(json.dumps(benches))
    del broken["slam.aces"]["rbpf"]["estimate_parts_s"]
    with pytest.raises(tables.BenchError, match=r"slam\.aces\.rbpf\.estimate_parts_s"):
        tables.parts_table(broken)


def test_prose_claims_hold_for_the_json():
    """What the Accuracy section says of the figures: below GMapping (published, and as measured
    here on intel and on every seed of aces), below Cartographer's published figures on every
    seed of intel, fr079, mit-csail and aces (aces' mean and largest seed named), and
    fr-clinic's mean and range."""
    benches = slam_benches()
    ours = {log: benches[f"slam.{log}"]["rbpf"]["trans_mean"] for log in ("intel", "aces", "fr079")}
    for log, error in ours.items():
        assert error < benches[f"slam.{log}"]["gmapping_published"], log
    measured = {log: tables.gmapping(benches[f"slam.{log}"])[0] for log in ours}
    assert ours["intel"] < float(measured["intel"].split(" ")[0])
    assert measured["fr079"] == "diverges"
    aces_seeds = benches["slam.aces"]["rbpf"]["per_seed"]
    assert max(s["trans_mean"] for s in aces_seeds) < float(measured["aces"].split(" ")[0])
    assert benches["slam.intel_classic"]["classic"]["trans_mean"] > 1.0  # "does not hold together"
    text = section("Accuracy")
    flat = " ".join(text.split())  # the claims, whatever the line wrapping
    assert "below GMapping's published figures on intel, aces and fr079" in flat
    assert "below GMapping as built and run here on intel, aces" in flat
    # Cartographer's published figures (Hess et al. 2016), as the README quotes them
    cartographer = {"intel": 0.0229, "fr079": 0.0452, "mit-csail": 0.0319, "aces": 0.0375}
    for log in ("intel", "fr079", "mit-csail", "aces"):
        seeds = benches[f"slam.{log}"]["rbpf"]["per_seed"]
        assert [s["seed"] for s in seeds] == [0, 1, 2, 3]
        assert max(s["trans_mean"] for s in seeds) < cartographer[log], log
        assert f"{log} ({cartographer[log]})" in flat
    assert (
        "below on intel (0.0229), fr079 (0.0452), mit-csail (0.0319) and aces (0.0375) on every "
        "seed 0–3" in flat
    )
    aces_mean = sum(s["trans_mean"] for s in aces_seeds) / len(aces_seeds)
    aces_max = max(s["trans_mean"] for s in aces_seeds)
    mean_fig = f"<!-- fig:slam.seed_mean_aces -->{aces_mean:.4f}<!-- /fig -->"
    max_fig = f"<!-- fig:slam.seed_max_aces -->{aces_max:.4f}<!-- /fig -->"
    assert f"(aces {mean_fig} on average over seeds 0–3, at most {max_fig})" in flat
    # mit-killian against Cartographer's 0.0395: the seeds below and above it, as written
    killian = [s["trans_mean"] for s in benches["slam.mit-killian"]["rbpf"]["per_seed"]]
    below = [k for k, v in enumerate(killian) if v < 0.0395]
    above = [k for k, v in enumerate(killian) if v >= 0.0395]
    assert (below, above) == ([0, 3], [1, 2])
    assert "below Cartographer on seeds 0 and 3, above on 1 and 2" in flat
    # the converged pose-graph solve's gain, against the capped solve on the same host
    over = benches["slam.mit-killian"]["rbpf"]["over_seeds"]
    assert (
        f"from 0.0423 to {over['trans_mean']['mean']:.4f} m and its map-quality score from 0.957 "
        f"to {over['quality_score']['mean']:.3f} on average" in flat
    )
    assert max(killian) < 0.122  # GMapping's published figure
    clinic = [s["trans_mean"] for s in benches["slam.fr-clinic"]["rbpf"]["per_seed"]]
    clinic_range = (
        f"<!-- fig:slam.seeds_fr-clinic -->{min(clinic):.3f}–{max(clinic):.3f}<!-- /fig -->"
    )
    clinic_mean = benches["slam.fr-clinic"]["rbpf"]["over_seeds"]["trans_mean"]["mean"]
    assert abs(clinic_mean - sum(clinic) / len(clinic)) < 1e-4
    mean_figure = f"<!-- fig:slam.seed_mean_fr-clinic -->{clinic_mean:.4f}<!-- /fig -->"
    assert (
        f"stays above the 0.10 m we aim at on average ({mean_figure} m; {clinic_range} m over "
        "seeds 0–3)" in flat
    )
    assert clinic_mean > 0.10


def test_the_online_table_shows_the_json_and_the_slowest_update_keeps_up():
    """The Performance section's ``Slam.update`` timings are docs/bench/online.json's, one row per
    log; its claim — the slowest update of every log took a fraction of the scan period — holds
    for the JSON; a skipped bench gets no row, and without any bench the share waits."""
    benches = json.loads((BENCH / "online.json").read_text())["benches"]
    performance = section("Performance")
    assert set(benches) >= {"online.demo", "online.intel", "online.fr-clinic"}
    for name, b in benches.items():
        row = (
            f"| {name.removeprefix('online.')} | {tables.thousands(b['scans'])} | "
            f"{tables.thousands(b['updates'])} | {tables.fixed(b['scan_period_ms'], 0)} | "
            f"{tables.fixed(b['update_median_ms'], 1)} | {tables.fixed(b['update_p99_ms'], 1)} | "
            f"{tables.fixed(b['update_max_ms'], 1)} | "
            f"{'—' if b['other_median_ms'] is None else tables.fixed(b['other_median_ms'], 2)} | "
            f"{tables.fixed(b['map_s'], 2)} | {tables.fixed(b['finish_s'], 1)} |"
        )
        assert row in performance, row
        assert b["update_max_ms"] < b["scan_period_ms"], name  # the prose: it keeps up
        assert b["update_median_ms"] <= b["update_p99_ms"] <= b["update_max_ms"], name
    share = max(100 * b["update_max_ms"] / b["scan_period_ms"] for b in benches.values())
    assert f"<!-- fig:online.worst_share -->{tables.fixed(share, 0)}<!-- /fig -->" in performance
    skipped = dict(benches, **{"online.intel": {"skipped": "absent"}})
    assert "| intel |" not in tables.online_table(skipped)
    assert "| demo |" in tables.online_table(skipped)
    assert tables.online_worst_share({"online.intel": {"skipped": "absent"}}) is None


def test_a_hand_edited_figure_is_named(tmp_path, capsys):
    readme = tmp_path / "README.md"
    text = README.read_text()
    wall = tables.fixed(slam_benches()["slam.demo_100"]["wall_s"], 1)
    row = f"| demo, rbpf, 100 particles | {wall} |"
    assert row in text
    readme.write_text(text.replace(row, "| demo, rbpf, 100 particles | 1.0 |"))
    assert tables.main(["--check", str(readme)]) == 1
    assert "'performance' differs" in capsys.readouterr().out
    assert tables.main([str(readme)]) == 0
    assert readme.read_text() == text


def test_a_missing_key_is_one_line_and_exit_2(tmp_path, capsys):
    benches = slam_benches()
    del benches["slam.aces"]["rbpf"]["trans_std"]
    write_bench(tmp_path, "slam", benches)
    assert tables.main(["--check", "--bench-dir", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["readme_tables: README.md: bench JSON: slam.aces.trans_std is missing"]


def test_a_missing_localize_key_names_the_file_and_table(tmp_path, capsys):
    benches = json.loads((BENCH / "localize.json").read_text())["benches"]
    del benches["localize.global_fr079"]["histogram_states"]
    write_bench(tmp_path, "localize", benches)
    page = ROOT / "docs" / "localize.md"
    assert tables.main(["--check", str(page), "--bench-dir", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        "readme_tables: docs/localize.md: docs/bench/localize.json: table localize.global needs "
        "the missing key 'histogram_states'"
    ]


def test_an_unknown_marker_is_named(tmp_path, capsys):
    readme = tmp_path / "README.md"
    readme.write_text("x <!-- fig:slam.nothing -->1<!-- /fig -->\n")
    assert tables.main([str(readme)]) == 2
    assert "unknown fig marker 'slam.nothing'" in capsys.readouterr().err


def test_extended_slam_json_adds_columns_and_logs():
    """A sweep's slam.json: per-seed figures, median, share > 0.2 m and a log more."""
    benches = slam_benches()
    for name in [
        k for k in benches if k.split(".")[1] in ("fr-clinic", "mit-csail", "mit-killian")
    ]:
        del benches[name]  # the JSON as it was before the sweep: the three known logs only
    for log in ("intel", "aces", "fr079"):
        for key in ("per_seed", "trans_median", "share_over_0.2m"):
            benches[f"slam.{log}"]["rbpf"].pop(key, None)
    seeds = [0.0263, 0.0205, 0.021, 0.0211]
    intel = benches["slam.intel"]["rbpf"]
    intel["per_seed"] = [{"seed": s, "trans_mean": e} for s, e in enumerate(seeds)]
    intel.update(trans_median=0.0195, **{"share_over_0.2m": 0.0123})
    clinic = copy.deepcopy(benches["slam.aces"])
    clinic["rbpf"].update(trans_mean=1.037, scans=6917)
    benches["slam.fr-clinic"] = clinic
    accuracy = tables.slam_table(benches).splitlines()
    assert accuracy[0].endswith("| over seeds (m) | median (m) | > 0.2 m |")
    intel_row = next(r for r in accuracy if r.startswith("| intel | **slam rbpf**"))
    assert intel_row.endswith("| 0.021–0.026 (seeds 0–3) | 0.020 | 1.2 % |")
    odometry_row = next(r for r in accuracy if r.startswith("| intel | odometry only"))
    odometry_wall = benches["slam.intel"]["odometry"]["wall_s"]
    assert odometry_row.endswith(f"| {odometry_wall:.1f} | | | |")  # no seed columns for it
    assert [r.split(" | ")[0] for r in accuracy[2:]].count("| fr-clinic") == 3
    assert accuracy[-3].startswith("| fr-clinic | odometry only")  # after fr079, the known logs
    assert tables.seed_range("intel")(benches) == "0.021–0.026"
    assert tables.seed_range("aces")(benches) is None
    performance = tables.performance_table(benches)
    assert "| fr-clinic (6 917 scans), rbpf, 30 particles |" in performance


def test_texture_figures_wait_for_texture_json_then_fill_in(tmp_path):
    write_bench(tmp_path, "slam", slam_benches())
    text = README.read_text()
    rendered, waiting = tables.render(text, tmp_path)
    assert rendered == text
    assert "fig texture.colour_mae (docs/bench/texture.json absent)" in waiting
    figures = {
        "colour_mae": 4.2051,
        "coverage": 0.9987,
        "frames_per_s": 96.4,
        "cpu_ms_per_frame": 9.23,
        "load_average_at_start": 4.2,
    }
    write_bench(tmp_path, "texture", {tables.TEXTURE: figures})
    rendered, waiting = tables.render(text, tmp_path)
    assert not any(w.startswith("fig texture.") and "slam_" not in w for w in waiting)
    floor = section_of(rendered, "Floor texture")
    assert "by <!-- fig:texture.colour_mae -->4.21<!-- /fig -->/255" in floor
    assert "floor to <!-- fig:texture.coverage -->100<!-- /fig --> %" in floor
    assert "ran at <!-- fig:texture.frames_per_s -->96<!-- /fig --> frames/s" in floor
    assert "with <!-- fig:texture.cpu_ms_per_frame -->9.2<!-- /fig --> ms" in floor
    assert "load average of <!-- fig:texture.load -->4<!-- /fig --> on" in floor
    assert "fig texture.slam_ate (its keys are not in docs/bench/texture.json yet)" in waiting
    run = {
        "ate_rmse": 0.0512,
        "colour_mae": 13.26,
        "coverage": 0.98749,
        "colour_mae_aligned": 8.04,
        "coverage_aligned": 0.9976,
        "map_offset_m": 0.0649,
        "map_offset_deg": 0.642,
    }
    write_bench(tmp_path, "texture", {tables.TEXTURE: figures, tables.TEXTURE_SLAM: run})
    rendered, waiting = tables.render(text, tmp_path)
    assert not any(w.startswith("fig texture.") for w in waiting)
    floor = section_of(rendered, "Floor texture")
    shown = [
        "ATE <!-- fig:texture.slam_ate -->0.051<!-- /fig --> m",
        "about <!-- fig:texture.slam_offset_cm -->6<!-- /fig --> cm",
        "<!-- fig:texture.slam_offset_deg -->0.6<!-- /fig -->° off",
        "error of <!-- fig:texture.slam_colour_mae -->13.3<!-- /fig -->/255",
        "<!-- fig:texture.slam_coverage -->98.7<!-- /fig --> %",
        "(<!-- fig:texture.slam_colour_mae_aligned -->8.0<!-- /fig -->/255",
    ]
    assert [fragment for fragment in shown if fragment not in floor] == []


@pytest.mark.parametrize(
    ("value", "digits", "expected"), [(27.15, 1, "27.2"), (0.0323, 3, "0.032"), (641.4, 0, "641")]
)
def test_fixed_rounds_halves_up_as_printed(value, digits, expected):
    assert tables.fixed(value, digits) == expected


def test_no_line_starts_with_an_inline_marker():
    """A line starting with ``<!--`` would begin an HTML block and break its paragraph."""
    for page in tables.PAGES:
        lines = (ROOT / page).read_text().splitlines()
        assert not [line for line in lines if line.startswith("<!-- fig:")], page


def test_localize_and_quality_tables_show_the_json_figures():
    localize = json.loads((BENCH / "localize.json").read_text())["benches"]
    quality = json.loads((BENCH / "quality.json").read_text())["benches"]
    page = (ROOT / "docs" / "localize.md").read_text()
    aces = localize["localize.global_aces"]
    assert f"| aces | **{aces['success']}/{aces['starts']}** |" in page
    step = f"{tables.fixed(aces['median_step_wall_ms'], 0)} / {tables.fixed(aces['median_step_cpu_ms'], 0)} ms"
    memory = f"{tables.fixed(aces['histogram_memory_mb'], 0)} MB"
    assert f"{tables.thousands(aces['histogram_states'])} | {memory} | {step} |" in page
    evaluation = (ROOT / "docs" / "evaluation.md").read_text()
    assert "@@" not in evaluation
    clinic = quality["quality.fr_clinic"]
    row = next(r for r in evaluation.splitlines() if r.startswith("| fr-clinic | 6 917 |"))
    assert f"| **{tables.fixed(clinic['score'], 3)}** |" in row
    r = clinic["relations"]  # bad stretches: all, ranked, flagged (fr-clinic has some)
    assert r["bad_stretches"] > 0
    bad = f"| {r['bad_stretches']} ({r['bad_stretches_judged']} / {r['bad_stretches_flagged']}) |"
    assert bad in row
    killian = quality["quality.mit_killian"]["relations"]  # re-timed relations
    row = next(r for r in evaluation.splitlines() if r.startswith("| mit-killian | 17 480 |"))
    assert (
        f"| {tables.fixed(killian['trans_mean'], 3)} / {tables.fixed(killian['trans_max'], 2)} |"
        in row
    )


def test_the_quality_table_lists_logs_scored_without_relations():
    """A log scored by the map quality score alone (metric "quality"): seed 0's score in bold, the
    range over seeds, wall, memory; mit-killian's relations bench carries the score beside its
    relations and is listed the same way."""
    benches = slam_benches()
    killian = benches["slam.mit-killian"]
    rows = tables.slam_quality_table(benches).splitlines()
    scores = [s["quality_score"] for s in killian["rbpf"]["per_seed"]]
    spread = f"{tables.fixed(min(scores), 3)}–{tables.fixed(max(scores), 3)} (seeds 0–3)"
    assert rows[3].startswith(
        f"| mit-killian | **slam rbpf** | **{tables.fixed(killian['rbpf']['quality_score'], 3)}**"
        f" | {spread} |"
    )
    benches = slam_benches()
    block = {"quality_score": 0.9, "wall_s": 100.04, "peak_rss_mb": 1000.4}
    block["per_seed"] = [{"seed": 0, "quality_score": 0.9}, {"seed": 1, "quality_score": 0.75}]
    benches["slam.mit-killian"] = {
        "metric": "quality",
        "quality": {"odometry": {"quality_score": 0.3, "wall_s": 30.0}, "rbpf": block},
    }
    rows = tables.slam_quality_table(benches).splitlines()
    assert rows[2] == "| mit-killian | odometry only | 0.300 | | 30.0 | |"
    assert (
        rows[3]
        == "| mit-killian | **slam rbpf** | **0.900** | 0.750–0.900 (seeds 0–1) | 100.0 | 1000 |"
    )
    del benches["slam.mit-killian"]
    assert len(tables.slam_quality_table(benches).splitlines()) == 2  # header only


def test_the_readme_shows_a_readable_picture_of_every_benchmark_log():
    """One map per log of ``tools/bench.py slam`` (``tools/bench_pictures.py``), in the README,
    at a size a reader can see and the repository can hold."""
    import cv2
    import numpy as np

    pictures = load_tool("bench_pictures")
    logs = pictures.picture_logs(json.loads((ROOT / "docs" / "bench" / "slam.json").read_text()))
    assert sorted(logs) == ["aces", "fr-clinic", "fr079", "intel", "mit-csail", "mit-killian"]
    readme = (ROOT / "README.md").read_text()
    for log in logs:
        path = ROOT / "docs" / "images" / f"slam-{log}.png"
        assert f'<img src="docs/images/slam-{log}.png"' in readme, log
        image = cv2.imread(str(path))
        assert image is not None, path
        assert 600 <= max(image.shape[:2]) <= 800, (log, image.shape)
        assert path.stat().st_size < 300_000, log
    wide = np.zeros((1586, 3000, 3), np.uint8)
    assert pictures.scaled(wide, 800).shape == (423, 800, 3)
    assert pictures.scaled(wide[:100, :200], 800).shape == (100, 200, 3)


def test_bench_pictures_refuse_a_bench_they_cannot_use(tmp_path, monkeypatch, capsys):
    """Exit 2 with the file and what was expected, and no picture written."""
    pictures = load_tool("bench_pictures")
    written = []
    monkeypatch.setattr(pictures, "write_png", lambda *a, **k: written.append(a))
    cases = {
        tmp_path / "absent.json": "expected the JSON tools/bench.py slam writes",
        tmp_path / "list.json": "expected the JSON tools/bench.py slam writes",
        tmp_path / "none.json": "expected SLAM benches with a sweep_dir, found none",
        tmp_path / "run.json": "quality.png: expected the bench run's quality picture",
    }
    (tmp_path / "list.json").write_text("[1, 2]")
    (tmp_path / "none.json").write_text(json.dumps({"benches": {"slam.demo_100": {}}}))
    run_dir = {"sweep_dir": str(tmp_path / "sweep")}
    (tmp_path / "run.json").write_text(json.dumps({"benches": {"slam.intel": run_dir}}))
    for bench, message in cases.items():
        monkeypatch.setattr("sys.argv", ["bench_pictures.py", "--bench", str(bench)])
        assert pictures.main() == 2
        err = capsys.readouterr().err
        assert message in err, err
    monkeypatch.setattr("sys.argv", ["bench_pictures.py", "--size", "0"])
    assert pictures.main() == 2
    assert "--size: expected a positive number of pixels, found 0" in capsys.readouterr().err
    assert written == []
