"""docs/architecture.md's import table matches the code (tools/import_graph.py)."""

from pathlib import Path

from tool_modules import load_tool

ROOT = Path(__file__).resolve().parents[1]


def test_the_import_table_in_the_architecture_doc_matches_the_code():
    tool = load_tool("import_graph")
    text = (ROOT / "docs/architecture.md").read_text(encoding="utf-8")
    assert tool._with_table(text) == text, "run: uv run python tools/import_graph.py --write"


def test_the_import_graph_sees_module_level_and_lazy_imports():
    graph = load_tool("import_graph").import_graph()
    now, later = graph["trajectory"]
    assert now == {"geometry"} and later == set()
    now, later = graph["stages"]
    assert "particle_filter" in now and "eval" in later  # the map-quality score, lazily
    # the kernels import nothing else of slam: they take arrays only
    assert graph["kernels"] == (set(), set())


def test_the_check_mode_reports_a_stale_doc(tmp_path, monkeypatch, capsys):
    tool = load_tool("import_graph")
    stale = tmp_path / "architecture.md"
    stale.write_text(f"x\n{tool.BEGIN}\n| old |\n{tool.END}\n", encoding="utf-8")
    monkeypatch.setattr(tool, "DOC", stale)
    assert tool.main(["--check"]) == 1
    assert "differs from the code" in capsys.readouterr().out
