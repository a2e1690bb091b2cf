"""``--force`` replaces only what slam wrote (:mod:`slam.io.runfolder`).

A finished output folder's marker lists every entry the folder held when it was finished;
``--force`` refuses (exit 2, one line, nothing changed) while the folder holds anything else: a
note of the user's, plots saved beside the outputs. A marker of an earlier release has no list:
then only the names the kind's writer produces are replaced. Fails on the code before the fix
(``--force`` replaced the whole folder, the user's files with it). The outputs are a 3 s
simulated log, a 20-scan run of it and a 20-scan localization on its map (a few seconds).
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import pytest
from cli_process import finished_run

from slam.cli import main
from slam.errors import UsageError
from slam.io import atomic
from slam.io.atomic import atomic_dir, check_output_dir
from slam.io.runfolder import (
    KINDS,
    LIST_HEADER,
    OWNER_FILE,
    foreign_entries,
    list_entries,
    read_marker_list,
)

RUN = ["--max-scans", "20", "--particles", "10", "--quiet"]


@pytest.fixture(scope="module")
def outputs(tmp_path_factory) -> dict[str, Path]:
    """A finished folder of every kind: ``sim`` (with RGB-D frames), ``run`` (with texture and
    recording) and ``localize`` (with recording)."""
    base = tmp_path_factory.mktemp("runfolder")
    sim = base / "sim"
    assert main(["sim", "small", "--out", str(sim), "--duration", "3", "--quiet"]) == 0
    run = finished_run(sim, base / "run", *RUN)
    loc = base / "loc"
    code = main(["localize", str(sim), "--map", str(run), "--initial=0,0,0,0.1",
                 "--max-scans", "20", "--out", str(loc), "--quiet"])  # fmt: skip
    assert code == 0
    return {"sim": sim, "run": run, "localize": loc}


def command(kind: str, outputs: dict[str, Path], out: Path) -> list[str]:
    """A quick command line of ``kind`` writing ``out``."""
    sim, run = outputs["sim"], outputs["run"]
    return {
        "run": ["run", str(sim), *RUN, "--no-record", "--seed", "3"],
        "sim": ["sim", "small", "--duration", "1", "--no-rgbd", "--seed", "3", "--quiet"],
        "localize": [
            "localize",
            str(sim),
            "--map",
            str(run),
            "--initial=0,0,0,0.1",
            "--max-scans",
            "10",
            "--no-record",
            "--quiet",
        ],  # fmt: skip
    }[kind] + ["--out", str(out), "--force"]


def snapshot(folder: Path) -> dict[str, bytes | None]:
    """Every entry under ``folder`` with its bytes (``None`` for a folder)."""
    return {
        str(p.relative_to(folder)): None if p.is_dir() else p.read_bytes()
        for p in sorted(folder.rglob("*"))
    }


def error_line(capsys) -> str:
    """The one line a refused command printed (no traceback)."""
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert err.startswith("slam: error: "), err
    return err[len("slam: error: ") : -1]


def no_partials(parent: Path) -> bool:
    return not [p for p in parent.iterdir() if p.name.endswith(".partial")]


def old_marker(folder: Path, kind: str) -> None:
    """Rewrite the marker of ``folder`` as a release before the list wrote it (its two lines)."""
    (folder / KINDS[kind].marker).write_text(KINDS[kind].marker_text())


@pytest.mark.parametrize("kind", ["run", "sim", "localize"])
def test_force_refuses_a_folder_holding_the_users_files_and_replaces_it_once_they_are_gone(
    kind, outputs, tmp_path, capsys
):
    """The bug: ``--force`` deleted ``my_notes.txt`` and ``plots/`` with the folder. Now it is
    one line, exit 2, and every file (the user's and the old outputs) is as it was; once the
    user's files are moved out the same command replaces the folder (a new one)."""
    out = shutil.copytree(outputs[kind], tmp_path / "out", symlinks=True)
    (out / "my_notes.txt").write_text("hi")
    (out / "plots").mkdir()
    (out / "plots" / "ape.pdf").write_bytes(b"%PDF")
    before = snapshot(out)
    assert main(command(kind, outputs, out)) == 2
    label = KINDS[kind].label
    assert error_line(capsys) == (
        f"{out}: --force replaces only what slam wrote, but this {label} also holds entries "
        "slam did not write (my_notes.txt, plots/); it was left alone (move them out or choose "
        "another --out)"
    )
    assert snapshot(out) == before and no_partials(tmp_path)

    (out / "my_notes.txt").unlink()
    shutil.rmtree(out / "plots")
    inode = out.stat().st_ino
    assert main(command(kind, outputs, out)) == 0
    assert out.stat().st_ino != inode and not (out / OWNER_FILE).exists()
    assert no_partials(tmp_path)
    required = KINDS[kind].required[0]
    assert (out / required).read_bytes() != before[required]  # the new outputs


def test_the_marker_lists_what_the_folder_held_sorted_after_its_constant_lines(outputs):
    """The list is every file and sub-folder (``/`` at the end), the marker included, sorted:
    equal outputs give an equal marker (the project compares the outputs of identical runs)."""
    sim = outputs["sim"]
    spec = KINDS["sim"]
    text = (sim / spec.marker).read_text()
    head, listed = text.split(LIST_HEADER + "\n")
    assert head == spec.marker_text()
    names = listed.splitlines()
    assert names == sorted(names) == list_entries(sim)
    assert ".slam-sim" in names and "dataRGBD/" in names and "dataRGBD/RGB20/" in names
    assert "dataRGBD/RGB20/rgb20_1.png" in names and "simulation.json" in names
    assert OWNER_FILE not in names
    assert read_marker_list(sim, "sim") == set(names)

    def finish(out: Path, order: list[str]) -> bytes:
        with atomic_dir(out, kind="run") as tmp:
            for name in order:
                (tmp / name).parent.mkdir(exist_ok=True)
                (tmp / name).write_text("x")
        return (out / ".slam-run").read_bytes()

    files = ["metrics.json", "config.toml", "sub/b.txt", "sub/a.txt"]
    first = finish(sim.parent / "same1", files)
    assert first == finish(sim.parent / "same2", files[::-1])
    assert first.decode().endswith(
        f"{LIST_HEADER}\n.slam-run\nconfig.toml\nmetrics.json\nsub/\nsub/a.txt\nsub/b.txt\n"
    )


@pytest.mark.parametrize("kind", ["run", "sim", "localize"])
def test_a_marker_without_a_list_allows_only_the_names_its_writer_produces(
    kind, outputs, tmp_path, capsys
):
    """A folder of an earlier release (its marker has no list) holding only names the kind's
    writer produces — here a real folder's — is replaced; one more name is refused and kept.
    This is also the check that :attr:`OutputKind.writes` covers what a real command writes."""
    out = shutil.copytree(outputs[kind], tmp_path / "out", symlinks=True)
    old_marker(out, kind)
    assert read_marker_list(out, kind) is None
    assert foreign_entries(out, kind) == []
    (out / "thesis.tex").write_text("years of work")
    (out / "config.toml.bak").write_text("mine")
    before = snapshot(out)
    assert main(command(kind, outputs, out)) == 2
    assert "(config.toml.bak, thesis.tex); it was left alone" in error_line(capsys)
    assert snapshot(out) == before

    (out / "thesis.tex").unlink()
    (out / "config.toml.bak").unlink()
    assert main(command(kind, outputs, out)) == 0
    assert read_marker_list(out, kind) == set(list_entries(out))  # a marker with its list


def test_what_later_slam_commands_add_to_a_run_folder_is_replaced_with_it(
    outputs, tmp_path, capsys
):
    """``slam export`` (default names, in ``export/``) and ``eval.json`` (``slam eval``, the
    sweep) are slam's though the marker does not list them; another file in ``export/`` is
    not."""
    out = shutil.copytree(outputs["run"], tmp_path / "out")
    assert main(["export", str(out), "--format", "kitti"]) == 0
    mine = out / "export" / "mine.tum"
    assert main(["export", str(out), "--format", "tum", "--out", str(mine)]) == 0
    (out / "eval.json").write_text("{}")
    capsys.readouterr()
    assert foreign_entries(out, "run") == ["export/mine.tum"]
    assert main(command("run", outputs, out)) == 2
    assert "(export/mine.tum)" in error_line(capsys)
    assert (out / "export" / "mine.tum").is_file() and (out / "eval.json").read_text() == "{}"

    (out / "export" / "mine.tum").unlink()
    assert main(command("run", outputs, out)) == 0
    assert not (out / "export").exists() and not (out / "eval.json").exists()
    assert json.loads((out / "metrics.json").read_text())["seed"] == 3


def test_the_message_names_five_entries_and_counts_the_rest(tmp_path):
    out = tmp_path / "out"
    with atomic_dir(out, kind="localize") as tmp:
        (tmp / "metrics.json").write_text("{}")
        (tmp / "config.toml").write_text("")
    for i in range(7):
        (out / f"note{i}.txt").write_text("mine")
    (out / "a\nb").write_text("mine")  # shown as its repr: the message stays one line
    os.symlink("/", out / "link")  # a link is an entry of its own, never followed
    with pytest.raises(UsageError) as exc:
        check_output_dir(out, "localize", force=True)
    assert str(exc.value) == (
        f"{out}: --force replaces only what slam wrote, but this localization folder also holds "
        "entries slam did not write ('a\\nb', link, note0.txt, note1.txt, note2.txt and 4 more); "
        "it was left alone (move them out or choose another --out)"
    )
    assert len(list(out.iterdir())) == 12 and no_partials(tmp_path)


def test_a_file_saved_into_the_folder_while_the_command_runs_is_kept(tmp_path):
    """The check is made again when the new folder is complete: a note saved meanwhile keeps the
    old folder (and the note), the new result is kept beside it (``out-2``), no partial folder
    is left."""
    out = tmp_path / "out"
    with atomic_dir(out, kind="run") as tmp:
        (tmp / "metrics.json").write_text('{"seed": 1}')
        (tmp / "config.toml").write_text("")
    with pytest.raises(UsageError) as late, atomic_dir(out, overwrite=True, kind="run") as tmp:
        (tmp / "metrics.json").write_text('{"seed": 2}')
        (tmp / "config.toml").write_text("")
        (out / "my_notes.txt").write_text("hi")
    assert str(late.value) == (
        f"{out}: --force replaces only what slam wrote, but this run folder also holds entries "
        "slam did not write (my_notes.txt); nothing was replaced (move them out or choose "
        f"another --out); this command's result is in {tmp_path / 'out-2'} instead"
    )
    assert (out / "metrics.json").read_text() == '{"seed": 1}'
    assert (out / "my_notes.txt").read_text() == "hi" and no_partials(tmp_path)
    kept = tmp_path / "out-2"
    assert (kept / "metrics.json").read_text() == '{"seed": 2}'
    assert sorted(p.name for p in kept.iterdir()) == [".slam-run", "config.toml", "metrics.json"]


@pytest.mark.parametrize("exchange", [True, False], ids=["rename-exchange", "move-aside"])
def test_a_file_saved_just_before_the_swap_is_kept_too(tmp_path, monkeypatch, exchange):
    """A note saved after that last check (simulated: the check passes without looking) is seen
    once the old folder is swapped out or moved aside: it is put back, nothing is deleted."""
    out = tmp_path / "out"
    with atomic_dir(out, kind="run") as tmp:
        (tmp / "metrics.json").write_text('{"seed": 1}')
        (tmp / "config.toml").write_text("")
    monkeypatch.setattr(atomic, "check_only_ours", lambda *args, **kwargs: None)
    if not exchange:
        monkeypatch.setattr(atomic, "_exchange", lambda a, b: False)
    (tmp_path / "out-2").mkdir()  # taken: the result goes to the next free name
    kept = tmp_path / "out-3"
    changed = pytest.raises(UsageError, match=f"this command's result is in {kept} instead$")
    with changed, atomic_dir(out, overwrite=True, kind="run") as tmp:
        (tmp / "metrics.json").write_text('{"seed": 2}')
        (tmp / "config.toml").write_text("")
        (out / "my_notes.txt").write_text("hi")
    assert sorted(p.name for p in out.iterdir()) == [
        ".slam-run", "config.toml", "metrics.json", "my_notes.txt"
    ]  # fmt: skip
    assert (out / "metrics.json").read_text() == '{"seed": 1}' and no_partials(tmp_path)
    assert (kept / "metrics.json").read_text() == '{"seed": 2}'
    assert not any((tmp_path / "out-2").iterdir())


def test_the_names_added_later_are_those_the_commands_write():
    """:attr:`OutputKind.added` and :attr:`OutputKind.writes` follow the constants of the code
    that writes the files (a renamed output must be renamed here too)."""
    from slam.eval.quality_run import PICTURE
    from slam.eval.report import EVAL_FILE
    from slam.io.ece276a import SPECS, rgbd_dirs, rgbd_patterns
    from slam.io.exports import DEFAULT_NAMES, EXPORT_DIR
    from slam.viz.recorder import RECORDING_NAME

    run = KINDS["run"]
    exports = {f"{EXPORT_DIR}/{n}" for n in DEFAULT_NAMES.values()}
    exports |= {f"{EXPORT_DIR}/map.yaml", f"{EXPORT_DIR}/trajectory_times.txt", f"{EXPORT_DIR}/"}
    assert {EVAL_FILE, PICTURE, *exports} <= set(run.added)
    assert {PICTURE, RECORDING_NAME, "texture.npz"} <= set(run.writes)
    sim = set(KINDS["sim"].writes)
    assert {spec.pattern.format(nn="*") for spec in SPECS.values()} <= sim
    rgb, disparity = (str(p) for p in rgbd_dirs(Path(""), "*"))
    rgb_name, disparity_name = (p.format("*") for p in rgbd_patterns("*"))
    assert {f"{rgb}/{rgb_name}", f"{disparity}/{disparity_name}", f"{rgb}/"} <= sim


def test_a_cache_dir_that_is_a_file_is_named(tmp_path, monkeypatch):
    """The bug: SLAM_CACHE_DIR pointing at a file ended in `slam: error: FILE: File exists`."""
    from slam.errors import UsageError
    from slam.io.datadir import resolve_cache_dir

    afile = tmp_path / "afile"
    afile.write_text("x")
    monkeypatch.setenv("SLAM_CACHE_DIR", str(afile))
    with pytest.raises(UsageError) as caught:
        resolve_cache_dir()
    assert str(caught.value) == (
        f"$SLAM_CACHE_DIR = {afile}: expected a folder for the generated datasets, found a file"
    )


def test_generated_data_never_goes_into_the_data_directory(tmp_path, monkeypatch):
    """The bug: without SLAM_CACHE_DIR the demo (171 MB) went to `<data dir>/cache` whenever the
    data directory was writable, `./data/cache` on a fresh checkout."""
    from slam.io.datadir import resolve_cache_dir

    monkeypatch.delenv("SLAM_CACHE_DIR", raising=False)
    monkeypatch.setenv("SLAM_DATA_DIR", str(tmp_path / "data"))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert resolve_cache_dir() == tmp_path / "xdg" / "slam"
    monkeypatch.delenv("XDG_CACHE_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert resolve_cache_dir() == tmp_path / "home" / ".cache" / "slam"
