"""Scenario files, the Udacity loader, the study and the ``slam grid`` command line."""

import json

import cv2
import pytest

from slam.cli import main
from slam.discrete.scenario import (
    load_scenario,
    load_udacity_cases,
    resolve_scenario,
    run_scenario,
    shipped_scenarios,
)
from slam.discrete.study import StudyConfig, ceiling_error, run_study
from slam.errors import ConfigError, DataError, UsageError

VALID = """
description = "tiny"
[world]
map = ["GRG", "G#R"]
legend = { G = "green", R = "red" }
[sensor]
type = "colour"
p_correct = 0.9
[motion]
type = "drift"
[run]
steps = ["sense red", "move E"]
"""


def write(tmp_path, text, name="s.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_shipped_scenarios_all_load_and_run():
    names = shipped_scenarios()
    assert {"obstacle-maze", "tutorial-1d", "colour-grid", "heading-maze"} <= set(names)
    for name in names:
        scenario = resolve_scenario(name)
        assert scenario.steps and scenario.description
        result = run_scenario(scenario)
        for record in result.steps:
            assert abs(record.belief.sum() - 1.0) < 1e-12


def test_heading_maze_recovers_cell_and_heading():
    result = run_scenario(resolve_scenario("heading-maze"))
    last = result.steps[-1]
    assert last.posterior[4, 3] > 0.95
    assert last.belief.sum(axis=(1, 2))[2] > 0.97  # facing S


def test_run_history_and_callback_for_a_recorder(tmp_path):
    scenario = load_scenario(write(tmp_path, VALID))
    seen = []
    result = run_scenario(scenario, on_step=seen.append)
    assert [r.after for r in seen] == ["sense", "move"]
    assert [r.action for r in result.steps] == ["red", "E"]
    first = result.steps[0].posterior
    assert first.shape == (2, 3)
    assert first[0, 1] == pytest.approx(0.9 / (0.9 * 2 + 0.1 * 3))
    assert first[1, 1] == 0.0


@pytest.mark.parametrize(
    "change, message",
    [
        (
            ("[run]", "[run]\nbogus = 1"),
            r"s.toml: run.bogus: unknown key; expected one of steps, threshold",
        ),
        (("p_correct = 0.9", 'p_correct = "high"'), r"s.toml: sensor.p_correct: expected a number"),
        (('type = "drift"', 'type = "teleport"'), r"s.toml: motion.type: expected one of"),
        (('"move E"', '"move up"'), r"s.toml: run.steps\[1\]: move 'up': expected one of N, E"),
        (('"sense red"', '"sense blue"'), r"run.steps\[0\]: unknown colour 'blue'"),
        (('"sense red"', '"look red"'), r"run.steps\[0\]: expected 'sense <observation>'"),
        (("[sensor]", "[prior]\nvalues = [1, 2]\n[sensor]"), r"prior.values: expected 2×3 values"),
        (
            ("[sensor]", "[prior]\nvalues = [[1, 0, 0], [0, 1, 0]]\n[sensor]"),
            r"obstacle cells must have prior probability 0",
        ),
        (
            ('map = ["GRG", "G#R"]', 'map = ["GRG", "G#"]'),
            r"s.toml: world.map\[1\]: .*equal length",
        ),
        (
            ('map = ["GRG", "G#R"]', 'map = ["GR.", "G#R"]'),
            r"s.toml: \[sensor\] colour sensor: every open cell needs a colour; cell \(0, 2\)",
        ),
        (
            ('description = "tiny"', "description = 3"),
            r"s.toml: description: expected a string, found 3",
        ),
        (
            ("[world]", "[world]\nheadings = 2"),
            r"s.toml: world.headings: expected one of 1, 4, found 2",
        ),
    ],
)
def test_bad_scenarios_name_file_and_key(tmp_path, change, message):
    old, new = change
    assert old in VALID
    text = VALID.replace(old, new, 1)
    with pytest.raises(ConfigError, match=message):
        load_scenario(write(tmp_path, text))


def test_impossible_observation_names_the_step(tmp_path, capsys):
    text = VALID.replace("p_correct = 0.9", "p_correct = 1.0").replace(
        '"sense red", "move E"', '"sense red", "move E", "sense red", "sense green"'
    )
    text = text.replace("[run]", "[prior]\nvalues = [[0, 1, 0], [0, 0, 0]]\n[run]")
    path = write(tmp_path, text)
    with pytest.raises(DataError, match=r"s.toml: step 3 \(sense green\): belief sums to 0.0"):
        run_scenario(load_scenario(path))
    assert main(["grid", "run", str(path)]) == 2
    assert "step 3 (sense green)" in capsys.readouterr().err


def test_valid_scenario_loads(tmp_path):
    scenario = load_scenario(write(tmp_path, VALID))
    assert scenario.world.shape == (2, 3) and scenario.world.open_count == 5
    assert scenario.world.palette == ("green", "red")
    assert scenario.name == "s" and scenario.threshold is None


def test_unknown_scenario_and_missing_file(tmp_path):
    with pytest.raises(UsageError, match="unknown scenario 'nowhere'; expected a TOML file"):
        resolve_scenario("nowhere")
    with pytest.raises(ConfigError, match="missing.toml: scenario file not found"):
        resolve_scenario(str(tmp_path / "missing.toml"))
    bad = write(tmp_path, "[world\nmap = 1")
    with pytest.raises(ConfigError, match="s.toml: invalid TOML"):
        load_scenario(bad)


def test_udacity_loader_rejects_malformed_files(tmp_path):
    path = tmp_path / "cases.json"
    path.write_text('{"cases_2d": [{"name": "x", "colors": [["G", "R"]]}]}')
    with pytest.raises(DataError, match=r"cases.json: cases_2d\[0\]: missing keys"):
        load_udacity_cases(path)
    path.write_text("{not json")
    with pytest.raises(DataError, match="cases.json: cannot read JSON"):
        load_udacity_cases(path)
    path.write_text(
        json.dumps(
            {
                "cases_2d": [
                    {
                        "name": "y",
                        "colors": [["G", "R"]],
                        "measurements": ["B"],
                        "motions": [[0, 0]],
                        "sensor_right": 0.7,
                        "p_move": 1.0,
                    }
                ]
            }
        )
    )
    with pytest.raises(DataError, match=r"cases_2d\[0\]: .*unknown colour 'B'"):
        load_udacity_cases(path)


# --- command line ------------------------------------------------------------------------------


def test_cli_obstacle_maze_prints_eight_tables(capsys):
    assert main(["grid", "run", "obstacle-maze"]) == 0
    out = capsys.readouterr().out
    assert out.count("Filtering after Evidence") == 4
    assert out.count("Prediction after Action") == 4
    assert "Filtering after Evidence [1, 0, 0, 0]" in out
    assert "Prediction after Action W" in out
    lines = out.splitlines()
    first = lines.index("Filtering after Evidence [0, 0, 0, 0]")
    assert lines[first + 2] == "  1.81   1.81  11.46  11.46   0.29     []   0.29"
    tables = [i for i, line in enumerate(lines) if "after" in line]
    assert len(tables) == 8
    assert all(len([c for c in lines[i + 1].split()]) == 7 for i in tables)


def test_cli_json_has_every_step(capsys):
    assert main(["grid", "run", "obstacle-maze", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert [s["after"] for s in data["steps"]] == ["sense", "move"] * 4
    assert data["steps"][1]["action"] == "N"
    posterior = data["steps"][0]["posterior"]
    assert posterior[1][5] is None
    assert posterior[1][2] == pytest.approx(0.1146, abs=1e-4)
    total = sum(v for row in posterior for v in row if v is not None)
    assert total == pytest.approx(1.0, abs=1e-12)


def test_cli_tutorial_json_numbers(capsys):
    assert main(["grid", "run", "tutorial-1d", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["steps"][0]["posterior"][0] == pytest.approx([0.4, 0.05, 0.05, 0.4, 0.1])


def test_cli_colour_grid_stops_when_localized(capsys):
    assert main(["grid", "run", "colour-grid"]) == 0
    out = capsys.readouterr().out
    assert "Localized: cell (8, 0) holds 99.91% (≥ 99.9%) after 14 observations" in out
    assert "  4.00   0.00" in out or "  0.00   4.00" in out


def test_cli_udacity_case(capsys, data_dir):
    assert main(["grid", "run", "udacity:c7", "--data-dir", str(data_dir)]) == 0
    out = capsys.readouterr().out
    assert "Expected posterior: max |difference| =" in out and "(ok)" in out


def test_cli_list_and_errors(capsys, tmp_path):
    assert main(["grid", "list", "--data-dir", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "obstacle-maze" in out and "udacity:<case>" in out
    assert main(["grid", "run", "no-such-scenario"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("slam: error: unknown scenario 'no-such-scenario'")
    assert len(err.strip().splitlines()) == 1
    assert main(["grid", "run", "udacity:c1", "--data-dir", str(tmp_path)]) == 2
    assert "Udacity test vectors not found" in capsys.readouterr().err


# --- study -----------------------------------------------------------------------------------


def test_study_is_seeded_and_writes_a_png(tmp_path, capsys):
    out = tmp_path / "study.png"
    args = ["grid", "study", "--sizes", "3,4", "--errors", "0.001,0.01", "--trials", "4"]
    args += ["--max-steps", "40", "--out", str(out), "--quiet"]
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "    3×3  0.001      4" in text
    image = cv2.imread(str(out))
    assert image is not None and image.shape[2] == 3 and image.shape[0] > 400
    # an existing file is replaced only with --force (a run replaces no file it did not make)
    assert main([*args, "--json"]) == 2
    assert capsys.readouterr().err == (
        f"slam: error: --out {out}: exists; it was left alone (choose another name, or give "
        "--force to replace it)\n"
    )
    assert main([*args, "--json", "--force"]) == 0
    rows = json.loads(capsys.readouterr().out)["rows"]
    assert [(r["size"], r["error"]) for r in rows] == [
        (3, 0.001),
        (3, 0.01),
        (4, 0.001),
        (4, 0.01),
    ]
    config = StudyConfig(sizes=(3, 4), errors=(0.001, 0.01), trials=4, max_steps=40)
    again = run_study(config)
    assert [(a.localized, a.correct, a.tracked) for a in again] == [
        (r["localized"], r["correct"], r["tracked"]) for r in rows
    ]


def test_study_ceiling_is_real():
    # K = 4, t = 0.999: above e ≈ 0.002994 no cell can reach the threshold after a move
    assert ceiling_error(4, 0.999) == pytest.approx(0.0029940, abs=1e-6)
    rows = run_study(StudyConfig(sizes=(4,), errors=(0.005,), trials=6, max_steps=30))
    assert rows[0].localized == 0
    rows = run_study(StudyConfig(sizes=(3,), errors=(0.0001,), trials=6, max_steps=30))
    assert rows[0].localized == 6 and rows[0].correct == 6


def test_study_rejects_bad_settings(capsys, tmp_path):
    with pytest.raises(
        UsageError, match=r"--errors: expected probabilities in \[0, 1\), found 1.5"
    ):
        StudyConfig(errors=(1.5,))
    for option, value, message in (
        ("--seed", "-1", "--seed: expected an integer ≥ 0, found -1"),  # was a numpy traceback
        ("--trials", "0", "--trials: expected at least 1, found 0"),
        ("--sizes", "0", "--sizes: expected grid sides ≥ 1, found 0"),
    ):
        assert main(["grid", "study", option, value, "--out", str(tmp_path / "s.png")]) == 2
        assert capsys.readouterr().err == f"slam: error: {message}\n"
    assert main(["grid", "study", "--sizes", "3,x", "--out", str(tmp_path / "a.png")]) == 2
    assert "--sizes '3,x': expected comma-separated numbers" in capsys.readouterr().err
    # the bug: the empty item was dropped without a word (exit 0)
    assert main(["grid", "study", "--sizes", "3,,5", "--out", str(tmp_path / "a.png")]) == 2
    assert capsys.readouterr().err == (
        "slam: error: --sizes '3,,5': expected comma-separated numbers, found an empty item\n"
    )
    assert main(["grid", "study", "--out", str(tmp_path / "a.jpg")]) == 2
