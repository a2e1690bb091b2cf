"""The bench tables and figures of README.md, docs/localize.md, docs/evaluation.md and docs/texture.md
(``PAGES``),
generated from ``docs/bench/*.json``.

Each generated part is marked with comments; everything between them is rewritten::

    <!-- table:slam -->            a whole table (the lines up to the closing marker)
    | log | method | ... |
    <!-- /table -->
    <!-- fig:slam.gmapping_speedup -->2.5–2.6<!-- /fig -->   inline: the text between the markers

(An inline marker must not start a line: ``<!--`` there would begin an HTML block.)

Usage::

    uv run python tools/readme_tables.py           # rewrite the pages from the JSON
    uv run python tools/readme_tables.py --check   # exit 1 and name each part that differs

A part whose JSON file is absent (``docs/bench/texture.json`` before its bench has been run), or
whose optional keys are (the per-seed figures before a sweep), is left as it is and reported as
waiting; a required key missing from a present file is an error (exit 2). ``TABLES`` and
``FIGURES`` list every marker name with its JSON file; ``docs/bench/localize.json`` and
``quality.json`` give one row per ``localize.tracking_<log>``, ``localize.global_<log>`` and
``quality.<log>`` bench.

What the generators read from ``docs/bench/slam.json`` (``benches`` of ``tools/bench.py slam``):

* ``slam.<log>`` / ``slam.<log>_<method>`` with an ``odometry`` block: an accuracy bench. Its
  ``method`` names the block with the filter's figures (``trans_mean``, ``trans_std``,
  ``rot_mean_deg``, ``rot_std_deg``, ``wall_s``; for the performance table also ``scans_per_s``,
  ``real_time_factor``, ``peak_rss_mb``, ``particles`` and ``scans`` (older files lack
  ``scans``: it is then ``scans_per_s × estimate_wall_s``, rounded)); ``gmapping_published``
  and ``gmapping_measured`` ("MEAN ± STD m in SECONDS s" or a word such as "diverges") give the
  GMapping row. Every log present gets its rows (known logs in ``LOG_ORDER`` first).
* ``slam.demo_*`` with ``ate_rmse``: a performance row of the simulated demo (its peak memory
  ``run_peak_rss_mb``, one run's, where the bench ran several).
* ``estimate_parts_s`` (seconds by part: the filter, then each post-filter stage) of
  ``slam.demo_100``, of every accuracy bench's method block and of ``quality.rbpf``: the
  ``performance.parts`` table, one column per part.
* Optional keys of a method block, shown as extra accuracy columns only when some log has them
  (a sweep over seeds writes them; see ``OPTIONAL_COLUMNS``): ``per_seed`` (a list of blocks
  with ``seed`` and ``trans_mean``), ``trans_median``, ``share_over_0.2m`` (fraction of
  relations). Unknown keys are ignored; a log the sweep adds gets rows in both tables.

``docs/bench/online.json`` (``tools/bench.py online``) gives the README's ``online`` table, one
row per ``online.<log>`` bench (``Slam.update`` timed call by call), and the share of the scan
period the slowest update took.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections.abc import Callable
from decimal import ROUND_HALF_UP, Decimal
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PAGES = ("README.md", "docs/localize.md", "docs/evaluation.md", "docs/texture.md")
"""The pages with generated parts, relative to the repository."""
BENCH_DIR = ROOT / "docs" / "bench"
LOG_ORDER = ("intel", "aces", "fr079", "fr-clinic", "mit-csail", "mit-killian")
BLOCK = re.compile(r"(<!-- table:([\w.-]+) -->\n)(.*?)(<!-- /table -->)", re.S)
INLINE = re.compile(r"(<!-- fig:([\w.-]+) -->)(.*?)(<!-- /fig -->)")

Benches = dict[str, dict]


class BenchError(Exception):
    """A bench file or key a page needs is malformed or missing (one line, exit 2)."""


def load_benches(name: str, bench_dir: Path = BENCH_DIR) -> Benches | None:
    """The ``benches`` of ``docs/bench/<name>.json``, or None when that file is absent."""
    path = bench_dir / f"{name}.json"
    if not path.is_file():
        return None
    try:
        return json.loads(path.read_text())["benches"]
    except (json.JSONDecodeError, KeyError, TypeError) as exc:
        raise BenchError(f"{path}: expected JSON with a 'benches' object ({exc})") from None


def get(benches: Benches, bench: str, *keys: str):
    """``benches[bench][key]...``, or a BenchError naming the missing key."""
    value = benches
    for key in (bench, *keys):
        if not isinstance(value, dict) or key not in value:
            raise BenchError(f"bench JSON: {'.'.join((bench, *keys))} is missing")
        value = value[key]
    return value


def table(header: list[str], rows: list[list[str]]) -> str:
    """A markdown table in the README's style (``|---|`` rules, ``| |`` for an empty cell)."""
    lines = [
        "|" + "|".join(f" {c} " if c else " " for c in cells) + "|" for cells in [header, *rows]
    ]
    lines.insert(1, "|" + "|".join("---" for _ in header) + "|")
    return "\n".join(lines) + "\n"


def fixed(value: float, digits: int) -> str:
    """``value`` with ``digits`` decimals, halves rounded up as a reader of the JSON would."""
    step = Decimal(1).scaleb(-digits)
    return str(Decimal(str(value)).quantize(step, rounding=ROUND_HALF_UP))


def thousands(n: int) -> str:
    """``13631`` as ``13 631`` (the README's digit grouping)."""
    return f"{n:,}".replace(",", " ")


# ---------------------------------------------------------------- slam.json


def accuracy_benches(benches: Benches) -> dict[str, list[tuple[str, dict]]]:
    """Per log (README order), its accuracy benches as (name, bench), ``slam.<log>`` first."""
    found: dict[str, list[tuple[str, dict]]] = {}
    for name, bench in sorted(benches.items()):
        if name.startswith("slam.") and isinstance(bench, dict) and "odometry" in bench:
            log = name.removeprefix("slam.").removesuffix(f"_{bench.get('method', 'rbpf')}")
            found.setdefault(log, []).append((name, bench))
    for log, runs in found.items():
        runs.sort(key=lambda run, log=log: run[0] != f"slam.{log}")

    def order(log: str) -> tuple[int, str]:
        return (LOG_ORDER.index(log) if log in LOG_ORDER else len(LOG_ORDER), log)

    return {log: found[log] for log in sorted(found, key=order)}


def _per_seed(block: dict) -> str:
    """``0.020–0.026 (seeds 0–3)``: the range of the per-seed mean translation errors."""
    seeds = sorted(block["per_seed"], key=lambda s: s["seed"])
    low, high = (fixed(f(s["trans_mean"] for s in seeds), 3) for f in (min, max))
    return f"{low}–{high} (seeds {seeds[0]['seed']}–{seeds[-1]['seed']})"


OPTIONAL_COLUMNS: tuple[tuple[str, str, Callable[[dict], str]], ...] = (
    ("per_seed", "over seeds (m)", _per_seed),
    ("trans_median", "median (m)", lambda b: fixed(b["trans_median"], 3)),
    ("share_over_0.2m", "> 0.2 m", lambda b: f"{fixed(100 * b['share_over_0.2m'], 1)} %"),
)


def _figures(block: dict, where: str) -> list[str]:
    """Translation, rotation and wall-time cells of a method block."""
    try:
        return [
            f"{fixed(block['trans_mean'], 3)} ± {fixed(block['trans_std'], 3)}",
            f"{fixed(block['rot_mean_deg'], 2)} ± {fixed(block['rot_std_deg'], 2)}",
            fixed(block["wall_s"], 1),
        ]
    except KeyError as exc:
        raise BenchError(f"bench JSON: {where}.{exc.args[0]} is missing") from None


def gmapping(bench: dict) -> tuple[str, str]:
    """GMapping's measured (error, wall seconds) from ``"0.029 ± 0.022 m in 70 s"``."""
    measured = str(bench.get("gmapping_measured", ""))
    found = re.fullmatch(r"(.+?) m in ([\d.]+) s", measured)
    return (found[1], found[2]) if found else (measured, "")


def slam_table(benches: Benches) -> str:
    """The Accuracy table: per log odometry, the default filter (bold), other runs, GMapping."""
    rows: list[list[str]] = []
    blocks: list[dict] = []  # the method block behind each row, for the optional columns
    for log, runs in accuracy_benches(benches).items():
        for name, bench in runs:
            method = bench.get("method", "rbpf")
            block = get(benches, name, method)
            if name == f"slam.{log}":
                rows.append(
                    [log, "odometry only", *_figures(bench["odometry"], f"{name}.odometry")]
                )
                bold = [f"**{c}**" for c in [f"slam {method}", *_figures(block, name)]]
                rows.append([log, *bold])
                blocks += [{}, block]
            else:
                particles = block.get("particles", "?")
                rows.append([log, f"slam {method} ({particles} particles)", *_figures(block, name)])
                blocks.append(block)
        default = dict(runs).get(f"slam.{log}", {})
        if "gmapping_published" in default:
            error, wall = gmapping(default)
            figure = f"{fixed(default['gmapping_published'], 3)} / {error}"
            rows.append(
                [log, "GMapping, published / measured here", figure, "", wall and f"— / {wall}"]
            )
            blocks.append({})
    header = ["log", "method", "translation (m)", "rotation (°)", "wall (s)"]
    for key, title, cell in OPTIONAL_COLUMNS:
        if any(key in b for b in blocks):
            header.append(title)
            for row, b in zip(rows, blocks, strict=True):
                row.append(cell(b) if key in b else "")
    return table(header, rows)


def _scans(block: dict) -> int:
    if "scans" in block:
        return int(block["scans"])
    return round(block["scans_per_s"] * block["estimate_wall_s"])


def performance_table(benches: Benches) -> str:
    """The Performance table: the demo benches, then the default filter on every log."""
    rows = []
    demos = [(n, b) for n, b in benches.items() if n.startswith("slam.demo") and "ate_rmse" in b]
    demos.sort(key=lambda nb: (nb[1]["method"] != "rbpf", nb[1]["method"], nb[1]["particles"]))
    for name, b in demos:
        run = f"demo, {b['method']}, {b['particles']} particles"
        rows.append([run, *_speed(b, name), fixed(b["ate_rmse"], 3)])
    for log, runs in accuracy_benches(benches).items():
        for name, bench in runs:
            method = bench.get("method", "rbpf")
            if name == f"slam.{log}":
                b = get(benches, name, method)
                run = f"{log} ({thousands(_scans(b))} scans), {method}, {b['particles']} particles"
                rows.append([run, *_speed(b, f"{name}.{method}"), "—"])
    header = ["run", "wall (s)", "scans/s", "real time ×", "peak RSS (MB)", "ATE RMSE (m)"]
    return table(header, rows)


def parts_table(benches: Benches) -> str:
    """Where the estimate's time goes, seed 0: the filter and each post-filter stage
    (``estimate_parts_s``), the demo at 100 particles and the default filter on every log."""
    runs: list[tuple[str, dict, str]] = []
    if "slam.demo_100" in benches:
        runs.append(("demo, 100 particles", get(benches, "slam.demo_100"), "slam.demo_100"))
    for log, entries in accuracy_benches(benches).items():
        for name, bench in entries:
            if name == f"slam.{log}":
                method = bench.get("method", "rbpf")
                runs.append((log, get(benches, name, method), f"{name}.{method}"))
    runs += [
        (name.removeprefix("slam."), b["quality"]["rbpf"], f"{name}.quality.rbpf")
        for name, b in benches.items()
        if b.get("metric") == "quality" and "rbpf" in b.get("quality", {})
    ]
    parts: list[str] = []
    for _, b, where in runs:
        if "estimate_parts_s" not in b:
            raise BenchError(f"bench JSON: {where}.estimate_parts_s is missing")
        parts += [k for k in b["estimate_parts_s"] if k not in parts]
    rows = []
    for label, b, _ in runs:
        seconds = b["estimate_parts_s"]
        rows.append(
            [label, *(fixed(seconds[k], 2) if k in seconds else "" for k in parts),
             fixed(sum(seconds.values()), 1)]
        )  # fmt: skip
    return table(["run", *parts, "sum (s)"], rows)


def online_table(benches: Benches) -> str:
    """``Slam.update`` per scan (``tools/benches/online.py``): per log the scans and updates, the
    scan period, the updates' median, 99th percentile and slowest call, the other scans' median,
    ``map()`` after the last scan (blank in a file from before it was timed) and ``finish()``."""
    rows = []
    logs = [n.removeprefix("online.") for n in benches if n.startswith("online.")]
    logs.sort(key=lambda log: (log != "demo", LOG_ORDER.index(log) if log in LOG_ORDER else 99))
    for log in logs:
        b = get(benches, f"online.{log}")
        if "skipped" in b:
            continue
        other = b["other_median_ms"]
        rows.append(
            [log, thousands(b["scans"]), thousands(b["updates"]), fixed(b["scan_period_ms"], 0),
             fixed(b["update_median_ms"], 1), fixed(b["update_p99_ms"], 1),
             fixed(b["update_max_ms"], 1), "—" if other is None else fixed(other, 2),
             fixed(b["map_s"], 2) if "map_s" in b else "", fixed(b["finish_s"], 1)]
        )  # fmt: skip
    header = [
        "log", "scans", "updates", "scan period (ms)", "update median (ms)", "update p99 (ms)",
        "slowest update (ms)", "other scans median (ms)", "`map()` at the end (s)",
        "`finish()` (s)",
    ]  # fmt: skip
    return table(header, rows)


def online_worst_share(benches: Benches) -> str | None:
    """The slowest ``Slam.update`` call as a share of the scan period (%), the largest of the
    logs timed (None before ``tools/bench.py online`` has run)."""
    runs = [b for n, b in benches.items() if n.startswith("online.") and "skipped" not in b]
    if not runs:
        return None
    return fixed(max(100.0 * b["update_max_ms"] / b["scan_period_ms"] for b in runs), 0)


def _speed(b: dict, where: str) -> list[str]:
    peak = "run_peak_rss_mb" if "run_peak_rss_mb" in b else "peak_rss_mb"  # (one run of several)
    try:
        keys = (("wall_s", 1), ("scans_per_s", 0), ("real_time_factor", 1), (peak, 0))
        return [fixed(b[key], digits) for key, digits in keys]
    except KeyError as exc:
        raise BenchError(f"bench JSON: {where}.{exc.args[0]} is missing") from None


def gmapping_speedup(benches: Benches) -> str:
    """How many times faster than GMapping as measured here, over the logs: ``2.5–2.6``."""
    ratios = []
    for log, runs in accuracy_benches(benches).items():
        default = dict(runs).get(f"slam.{log}", {})
        if wall := gmapping(default)[1]:
            method = default.get("method", "rbpf")
            ratios.append(float(wall) / get(benches, f"slam.{log}", method, "wall_s"))
    if not ratios:
        raise BenchError("bench JSON: no slam.<log> bench has a GMapping wall time")
    low, high = fixed(min(ratios), 1), fixed(max(ratios), 1)
    return low if low == high else f"{low}–{high}"


def seed_range(log: str) -> Callable[[Benches], str | None]:
    """``0.020–0.026``: the per-seed mean translation errors of a log (None before a sweep)."""

    def figure(benches: Benches) -> str | None:
        block = get(benches, f"slam.{log}", "rbpf")
        return _per_seed(block).split(" ")[0] if "per_seed" in block else None

    return figure


def _figure(*keys: str, digits: int | None = None) -> Callable[[Benches], str]:
    """The figure at ``benches[keys[0]][keys[1]]...``, with ``digits`` decimals (None: as is)."""

    def figure(benches: Benches) -> str:
        value = get(benches, *keys)
        return str(value) if digits is None else fixed(value, digits)

    return figure


TEXTURE = "texture.demo_ground_truth_path"
"""The texture bench of the README: the demo along its true path (tools/benches/texture.py)."""
TEXTURE_SLAM = "texture.demo_slam_run"
"""``slam run demo``'s texture along its SLAM trajectory (tools/benches/texture.py)."""


def _slam_texture(key: str, digits: int, scale: float = 1.0) -> Callable[[Benches], str | None]:
    """A figure of :data:`TEXTURE_SLAM` times ``scale`` (None, waiting, in a texture.json
    written before that bench existed)."""

    def figure(benches: Benches) -> str | None:
        if TEXTURE_SLAM not in benches:
            return None
        return fixed(scale * get(benches, TEXTURE_SLAM, key), digits)

    return figure


COLD = "coldstart.demo_cold_then_warm"
"""The cold-start bench: ``slam run demo`` on a fresh numba cache, then again (tools/benches/coldstart.py)."""
NOBG = "coldstart.demo_cold_without_background"
"""The cold run with ``SLAM_BACKGROUND_COMPILE=0`` (every kernel compiled by the run itself)."""
WARMUP = "coldstart.warmup_then_run"
"""``slam warmup`` on a fresh numba cache, then ``slam run demo``."""


def _percent(*keys: str) -> Callable[[Benches], str]:
    return lambda benches: fixed(100 * get(benches, *keys), 0)


# ---------------------------------------------------------------- localize.json, quality.json


def _log_benches(benches: Benches, prefix: str) -> list[tuple[str, dict]]:
    """(log, bench) of the benches ``<prefix><log>`` (``fr_clinic`` → ``fr-clinic``), README order."""
    found = [
        (name.removeprefix(prefix).replace("_", "-"), bench)
        for name, bench in benches.items()
        if name.startswith(prefix)
    ]
    return sorted(found, key=lambda lb: (LOG_ORDER.index(lb[0]) if lb[0] in LOG_ORDER else 99, lb))


def _relation_cell(r: dict, digits: int, bold: bool = False) -> str:
    """``0.0253 ± 0.0229, 0.30``: translation mean ± std (m), rotation mean (°)."""
    mean = fixed(r["trans_mean"], digits)
    mean = f"**{mean}**" if bold else mean
    return f"{mean} ± {fixed(r['trans_std'], digits)}, {fixed(r['rot_mean_deg'], 2)}"


def tracking_table(benches: Benches) -> str:
    """docs/localize.md: tracking from the true start pose, per log."""
    rows = []
    for log, b in _log_benches(benches, "localize.tracking_"):
        pose = b["pose_vs_slam"]
        rows.append([
            log, _relation_cell(b["slam"], 4), _relation_cell(b["localize"], 4, bold=True),
            fixed(b["trans_ratio_to_slam"], 2),
            f"{fixed(100 * pose['median_m'], 1)} cm, {fixed(pose['median_deg'], 2)}°",
            f"{fixed(100 * b['localized_share'], 2)} %", fixed(b["estimate_wall_s"], 1),
            fixed(b["estimate_cpu_s"], 1),
            f"{fixed(b['real_time_factor'], 0)} / {fixed(b['real_time_factor_cpu'], 0)}",
        ])  # fmt: skip
    header = ["log", "SLAM run (m, °)", "`slam localize` (m, °)", "ratio", "pose vs SLAM, median",
              "localized", "wall (s)", "CPU (s)", "real time × (wall / CPU)"]  # fmt: skip
    return table(header, rows)


def global_table(benches: Benches) -> str:
    """docs/localize.md: global localization from seeded start times, per log."""
    rows = []
    for log, b in _log_benches(benches, "localize.global_"):
        n = b["starts"]
        rows.append([
            log, f"**{b['success']}/{n}**", f"{b['first_convergence_correct']}/{n}",
            str(b["wrong_and_stayed"]), f"{b['median_driven_m']} m",
            f"{fixed(b['median_time_s'], 1)} s / {fixed(b['max_time_s'], 1)} s",
            thousands(b["histogram_states"]), f"{fixed(b['histogram_memory_mb'], 0)} MB",
            f"{fixed(b['median_step_wall_ms'], 0)} / {fixed(b['median_step_cpu_ms'], 0)} ms",
        ])  # fmt: skip
    header = ["log", "success", "first convergence correct", "wrong and stayed", "median driven",
              "median / longest time", "states", "histogram memory",
              "step wall / CPU (median)"]  # fmt: skip
    return table(header, rows)


def quality_table(benches: Benches) -> str:
    """docs/evaluation.md: the map score of ``slam run LOG`` beside its relation errors."""
    rows = []
    for log, b in _log_benches(benches, "quality."):
        if "score" not in b:
            continue  # the synthetic bench: quality_synthetic_table
        r = b.get("relations") or {}
        relations = [
            f"{fixed(r['trans_mean'], 3)} / {fixed(r['trans_max'], 2)}",
            f"{fixed(100 * r['share_over_0.2m'], 1)} %",
            f"{r['bad_stretches']} ({r['bad_stretches_judged']} / {r['bad_stretches_flagged']})",
        ] if r else ["—", "—", "—"]  # fmt: skip
        rows.append([
            log, thousands(b["scans"]), fixed(b["path_length_m"], 0), f"**{fixed(b['score'], 3)}**",
            f"{fixed(100 * b['coverage'], 0)} %", f"{b['judged_stretches']} / {b['stretches']}",
            f"{fixed(b['median_stretch_score'], 3)} / {fixed(b['worst_score'], 3)}",
            str(b["flagged"]), *relations,
            f"{fixed(b['quality_wall_s'], 1)} ({fixed(100 * b['quality_share_of_run'], 1)} %)",
        ])  # fmt: skip
    header = ["log", "scans", "path (m)", "score", "coverage", "ranked / stretches",
              "median / worst stretch", "flagged", "relation error mean / max (m)", "> 0.2 m",
              "bad stretches (ranked / flagged)", "score time (s, share of run)"]  # fmt: skip
    return table(header, rows)


def quality_synthetic_table(benches: Benches) -> str:
    """docs/evaluation.md: the demo building's true trajectory and the same with its loop opened."""
    rows = []
    for key, label in (("truth", "true trajectory"), ("opened_loop", "loop opened")):
        b = get(benches, "quality.synthetic", key)
        rows.append([label, f"**{fixed(b['score'], 3)}**", fixed(b["worst_score"], 3),
                     str(b["flagged"]), str(b["judged_stretches"])])  # fmt: skip
    return table(["demo", "score", "worst stretch", "flagged", "ranked stretches"], rows)


def _same(*values: Callable[[Benches], float], digits: int) -> Callable[[Benches], str]:
    """One figure for several benches: ``0.99``, or ``0.92–0.94`` when they differ."""

    def figure(benches: Benches) -> str:
        shown = sorted({fixed(v(benches), digits) for v in values}, key=float)
        return shown[0] if len(shown) == 1 else f"{shown[0]}–{shown[-1]}"

    return figure


def _per_log(prefix: str, key: str, digits: int, last: str = ", ") -> Callable[[Benches], str]:
    """``310, 376 and 242``: one figure per log of the ``<prefix><log>`` benches, README order."""

    def figure(benches: Benches) -> str:
        shown = [fixed(b[key], digits) for _, b in _log_benches(benches, prefix)]
        return ", ".join(shown[:-1]) + last + shown[-1] if len(shown) > 1 else "".join(shown)

    return figure


def _at(*keys: str) -> Callable[[Benches], float]:
    return lambda benches: get(benches, *keys)


def map_quality_benches(benches: Benches) -> dict[str, dict]:
    """Logs whose bench gives the map quality score (seeds 0–3): those without time-matched
    relations (``metric = "quality"``) and those whose relations were re-timed (mit-killian),
    README order."""
    found = {
        name.removeprefix("slam."): bench
        for name, bench in benches.items()
        if name.startswith("slam.")
        and isinstance(bench, dict)
        and (
            bench.get("metric") == "quality"
            or "quality_score" in bench.get("rbpf", {}).get("over_seeds", {})
        )
    }
    return dict(sorted(found.items(), key=lambda kv: (kv[0] not in LOG_ORDER, kv[0])))


def slam_quality_table(benches: Benches) -> str:
    """The map quality score (seed 0, range over seeds), wall, peak memory of the logs of
    :func:`map_quality_benches`."""
    rows = []
    for log, bench in map_quality_benches(benches).items():
        name = f"slam.{log}"
        keys = ("quality",) if bench.get("metric") == "quality" else ()
        odometry = get(benches, name, *keys, "odometry")
        rbpf = get(benches, name, *keys, "rbpf")
        rows.append(
            [log, "odometry only", fixed(odometry["quality_score"], 3), "",
             fixed(odometry["wall_s"], 1), ""]
        )  # fmt: skip
        scores = [s["quality_score"] for s in rbpf.get("per_seed", [])]
        seeds = [s["seed"] for s in rbpf.get("per_seed", [])]
        spread = (
            f"{fixed(min(scores), 3)}–{fixed(max(scores), 3)} (seeds {min(seeds)}–{max(seeds)})"
            if scores
            else ""
        )
        rows.append(
            [log, "**slam rbpf**", f"**{fixed(rbpf['quality_score'], 3)}**", spread,
             fixed(rbpf["wall_s"], 1), f"{rbpf['peak_rss_mb']:.0f}"]
        )  # fmt: skip
    header = ["log", "method", "map quality score", "over seeds", "wall (s)", "peak RSS (MB)"]
    return table(header, rows)


# name -> (JSON file stem, generator)
TABLES: dict[str, tuple[str, Callable[[Benches], str]]] = {
    "slam": ("slam", slam_table),
    "performance": ("slam", performance_table),
    "performance.parts": ("slam", parts_table),
    "online": ("online", online_table),
    "slam.quality": ("slam", slam_quality_table),
    "localize.tracking": ("localize", tracking_table),
    "localize.global": ("localize", global_table),
    "quality": ("quality", quality_table),
    "quality.synthetic": ("quality", quality_synthetic_table),
}


# marker name -> generator; the JSON file is the name's first part (``localize.x``: localize.json)
_FIGURES: dict[str, Callable[[Benches], str | None]] = {
    "online.worst_share": online_worst_share,
    "slam.particles": _figure("slam.intel", "rbpf", "particles"),
    "slam.gmapping_speedup": gmapping_speedup,
    "slam.aces_gmapping": lambda b: gmapping(get(b, "slam.aces"))[0].split(" ")[0],
    "slam.aces_rbpf": _figure("slam.aces", "rbpf", "trans_mean", digits=3),
    "slam.seeds_intel": seed_range("intel"),
    "slam.seeds_aces": seed_range("aces"),
    "slam.seeds_fr079": seed_range("fr079"),
    "slam.seeds_fr-clinic": seed_range("fr-clinic"),
    "slam.seeds_mit-killian": seed_range("mit-killian"),
    "slam.seed_mean_fr-clinic": _figure(
        "slam.fr-clinic", "rbpf", "over_seeds", "trans_mean", "mean", digits=4
    ),
    "slam.seed_mean_aces": _figure(
        "slam.aces", "rbpf", "over_seeds", "trans_mean", "mean", digits=4
    ),
    "slam.seed_max_aces": _figure("slam.aces", "rbpf", "over_seeds", "trans_mean", "max", digits=4),
    "slam.seed_mean_mit-killian": _figure(
        "slam.mit-killian", "rbpf", "over_seeds", "trans_mean", "mean", digits=4
    ),
    "slam.demo_scans": _figure("slam.demo_100", "scans"),
    "slam.classic_path": _figure("slam.demo_classic_100", "path_length_m", digits=1),
    "slam.true_path": _figure("slam.demo_classic_100", "true_path_length_m", digits=1),
    "quality.good_score": _same(
        _at("quality.intel", "score"), _at("quality.fr079", "score"), digits=2
    ),
    "quality.good_worst": _same(
        _at("quality.intel", "worst_score"), _at("quality.fr079", "worst_score"), digits=2
    ),
    "localize.particles": _per_log("localize.tracking_", "particles_mean", 0, " and "),
    "localize.match_quality": _per_log("localize.tracking_", "mean_match_quality", 2),
    "localize.peak_rss_intel": _figure("localize.tracking_intel", "peak_rss_mb", digits=0),
    "localize.map_memory_intel": _figure("localize.tracking_intel", "map_memory_mb", digits=1),
    "localize.cross_run_mean": _figure(
        "localize.cross_run_intel", "localize", "trans_mean", digits=3
    ),
    "localize.cross_run_std": _figure(
        "localize.cross_run_intel", "localize", "trans_std", digits=3
    ),
    "localize.kidnap_noticed": _figure("localize.kidnap_intel", "noticed_after_s", digits=1),
    "localize.kidnap_recovered": _figure("localize.kidnap_intel", "recovered_after_s", digits=1),
    "localize.step_median_ms": _figure(
        "localize.histogram_step_intel", "step_wall_ms_median", digits=1
    ),
    "localize.step_least_ms": _figure(
        "localize.histogram_step_intel", "step_wall_ms_min", digits=1
    ),
    "viz.recorder_pct": _figure("viz.demo_overhead", "recorder_pct", digits=1),
    "viz.wall_difference_pct": _figure("viz.demo_overhead", "wall_difference_pct", digits=1),
    "viz.recording_mb": _figure("viz.demo_overhead", "recording_mb", digits=1),
    "texture.colour_mae": _figure(TEXTURE, "colour_mae", digits=2),
    "texture.coverage": _percent(TEXTURE, "coverage"),
    "texture.frames_per_s": _figure(TEXTURE, "frames_per_s", digits=0),
    "texture.cpu_ms_per_frame": _figure(TEXTURE, "cpu_ms_per_frame", digits=1),
    "texture.load": _figure(TEXTURE, "load_average_at_start", digits=0),
    "texture.slam_ate": _slam_texture("ate_rmse", 3),
    "texture.slam_colour_mae": _slam_texture("colour_mae", 1),
    "texture.slam_coverage": _slam_texture("coverage", 1, scale=100),
    "texture.slam_colour_mae_aligned": _slam_texture("colour_mae_aligned", 1),
    "texture.slam_coverage_aligned": _slam_texture("coverage_aligned", 1, scale=100),
    "texture.slam_offset_cm": _slam_texture("map_offset_m", 0, scale=100),
    "texture.slam_offset_deg": _slam_texture("map_offset_deg", 1),
    "sim.demo_wall_s": _figure("sim.demo_full", "wall_s", digits=0),
    "sim.demo_20hz_wall_s": _figure("sim.demo_rgbd_20hz", "wall_s", digits=0),
    "sim.load": _figure("sim.demo_full", "load_average_at_start", digits=0),
    "coldstart.cold_wall_s": _figure(COLD, "cold", "wall_s", digits=0),
    "coldstart.cold_cpu_s": _figure(COLD, "cold", "cpu_s", digits=0),
    "coldstart.cold_compile_s": _figure(COLD, "cold", "compile_s", digits=0),
    "coldstart.cold_compile_cpu_s": _figure(COLD, "cold", "compile_cpu_s", digits=0),
    "coldstart.cold_background_cpu_s": _figure(
        COLD, "cold", "compile_background", "compile_cpu_s", digits=0
    ),
    "coldstart.cold_estimate_compile_s": _figure(COLD, "cold", "estimate_compile_s", digits=1),
    "coldstart.nobg_wall_s": _figure(NOBG, "cold", "wall_s", digits=0),
    "coldstart.nobg_compile_s": _figure(NOBG, "cold", "compile_s", digits=0),
    "coldstart.nobg_load": _figure(NOBG, "cold", "load_average_at_start", digits=0),
    "coldstart.warm_wall_s": _figure(COLD, "warm", "wall_s", digits=0),
    "coldstart.warm_cpu_s": _figure(COLD, "warm", "cpu_s", digits=0),
    "coldstart.warm_ate": _figure(COLD, "warm", "ate_rmse", digits=3),
    "coldstart.load": _figure(COLD, "cold", "load_average_at_start", digits=0),
    "coldstart.warmup_wall_s": _figure(WARMUP, "warmup", "wall_s", digits=0),
    "coldstart.warmup_cpu_s": _figure(WARMUP, "warmup", "cpu_s", digits=0),
    "coldstart.after_warmup_compile_s": _figure(WARMUP, "run", "compile_s", digits=1),
}
FIGURES: dict[str, tuple[str, Callable[[Benches], str | None]]] = {
    name: (name.split(".")[0], generator) for name, generator in _FIGURES.items()
}


def render(text: str, bench_dir: Path = BENCH_DIR) -> tuple[str, list[str]]:
    """``text`` with every marked part regenerated, and the parts waiting for an absent JSON."""
    cache: dict[str, Benches | None] = {}
    waiting: list[str] = []

    def generate(kind: str, registry: dict, match: re.Match) -> str:
        name = match[2]
        if name not in registry:
            raise BenchError(
                f"unknown {kind} marker '{name}' (known: {', '.join(sorted(registry))})"
            )
        source, generator = registry[name]
        if source not in cache:
            cache[source] = load_benches(source, bench_dir)
        if cache[source] is None:
            waiting.append(f"{kind} {name} (docs/bench/{source}.json absent)")
            return match[0]
        try:
            generated = generator(cache[source])
        except (KeyError, TypeError) as exc:
            raise BenchError(
                f"docs/bench/{source}.json: {kind} {name} needs the missing key {exc}"
            ) from None
        if generated is None:
            waiting.append(f"{kind} {name} (its keys are not in docs/bench/{source}.json yet)")
            return match[0]
        return match[1] + generated + match[4]

    text = BLOCK.sub(lambda m: generate("table", TABLES, m), text)
    text = INLINE.sub(lambda m: generate("fig", FIGURES, m), text)
    return text, waiting


def differences(old: str, new: str) -> list[str]:
    """The names of the marked parts whose content differs between two versions of a page."""
    parts = [BLOCK, INLINE]
    before = {(p.pattern, m[2], i): m[3] for p in parts for i, m in enumerate(p.finditer(old))}
    after = {(p.pattern, m[2], i): m[3] for p in parts for i, m in enumerate(p.finditer(new))}
    return sorted({key[1] for key in before if before[key] != after.get(key)})


def main(argv: list[str] | None = None) -> int:
    """Rewrite the pages' generated parts, or with ``--check`` report those that are stale."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("pages", nargs="*", type=Path, help="markdown files (default: PAGES)")
    parser.add_argument("--check", action="store_true", help="only report stale parts (exit 1)")
    parser.add_argument("--bench-dir", type=Path, default=BENCH_DIR, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    stale_pages = 0
    for page in args.pages or [ROOT / name for name in PAGES]:
        page = page.resolve()
        old = page.read_text()
        shown = page.relative_to(ROOT) if page.is_relative_to(ROOT) else page
        try:
            new, waiting = render(old, args.bench_dir)
        except BenchError as exc:
            print(f"readme_tables: {shown}: {exc}", file=sys.stderr)
            return 2
        for part in waiting:
            print(f"{shown}: waiting: {part}", file=sys.stderr)
        stale = differences(old, new)
        stale_pages += bool(stale)
        if args.check:
            for name in stale:
                print(f"{shown}: '{name}' differs from docs/bench (run tools/readme_tables.py)")
        elif stale:
            page.write_text(new)
            print(f"{shown}: rewritten: {', '.join(stale)}")
    return 1 if args.check and stale_pages else 0


if __name__ == "__main__":
    sys.exit(main())
