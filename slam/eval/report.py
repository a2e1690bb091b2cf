"""The thin report layer of evaluation: the text table of ``slam eval`` and ``eval.json``.

The result is one JSON-ready dictionary: ``{"relations": {...}}`` for the relation metric, flat
``ate_*`` / ``rpe_*`` keys for a reference trajectory and ``{"quality": {...}}`` for the map score
without ground truth (each when asked for), plus the paths evaluated. Non-finite numbers (a statistic over nothing) are written as ``null``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from slam.io.atomic import write_text

EVAL_FILE = "eval.json"
"""Name of the evaluation report inside a run folder."""


def _finite(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    return value


def to_json(result: dict[str, Any]) -> str:
    """The result as indented JSON text (NaN and inf become ``null``)."""
    return json.dumps(_finite(result), indent=2, allow_nan=False) + "\n"


def write_eval_json(run_dir: Path, result: dict[str, Any]) -> Path:
    """Write ``run_dir/eval.json`` atomically; return its path."""
    path = Path(run_dir) / EVAL_FILE
    write_text(path, to_json(result))
    return path


def _fmt(value: Any, unit: str = "", digits: int = 4) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "n/a"
    if isinstance(value, float):
        return f"{value:.{digits}f}{unit}"
    return f"{value}{unit}"


def format_table(result: dict[str, Any]) -> str:
    """Human-readable table of a result (what ``slam eval`` prints without ``--json``)."""
    rows: list[tuple[str, str]] = [
        ("trajectory", f"{result.get('trajectory', '')} ({result.get('poses', '?')} poses)")
    ]
    rel = result.get("relations")
    if rel is not None:
        rows += [
            ("relations", str(rel.get("file", ""))),
            (
                "  matched",
                f"{rel['count']} of {rel['total']} ({rel['unmatched']} unmatched, "
                f"tolerance {rel['tolerance_s']:g} s)",
            ),
            (
                "  translation",
                f"mean {_fmt(rel['trans_mean'], ' m')}  std {_fmt(rel['trans_std'], ' m')}  "
                f"max {_fmt(rel['trans_max'], ' m')}",
            ),
            (
                "  rotation",
                f"mean {_fmt(rel['rot_mean_deg'], '°', 3)}  std {_fmt(rel['rot_std_deg'], '°', 3)}"
                f"  max {_fmt(rel['rot_max_deg'], '°', 3)}",
            ),
            (
                "  squared",
                f"trans {_fmt(rel['trans_sq_mean'], ' m²')} ± {_fmt(rel['trans_sq_std'], ' m²')}"
                f"  rot {_fmt(rel['rot_sq_mean_deg2'], ' deg²', 3)} ± "
                f"{_fmt(rel['rot_sq_std_deg2'], ' deg²', 3)}",
            ),
        ]
    if "ate_rmse" in result:
        rows += [
            ("reference", str(result.get("reference", ""))),
            (
                "  matched",
                _matched(result),
            ),
            (
                "  alignment",
                f"{result['alignment']}: x {_fmt(result['alignment_x'], ' m', 3)}, "
                f"y {_fmt(result['alignment_y'], ' m', 3)}, "
                f"yaw {_fmt(result['alignment_yaw_deg'], '°', 3)}",
            ),
            (
                "  ATE",
                f"rmse {_fmt(result['ate_rmse'], ' m')}  mean {_fmt(result['ate_mean'], ' m')}"
                f"  median {_fmt(result['ate_median'], ' m')}  max {_fmt(result['ate_max'], ' m')}"
                f"  heading rmse {_fmt(result['ate_rot_rmse_deg'], '°', 3)}",
            ),
            (
                "  RPE",
                f"{result['rpe_pairs']} pairs {result['rpe_delta']:g} {result['rpe_delta_unit']}"
                f" apart: trans mean {_fmt(result['rpe_trans_mean'], ' m')}"
                f"  rmse {_fmt(result['rpe_trans_rmse'], ' m')}"
                f"  rot mean {_fmt(result['rpe_rot_mean_deg'], '°', 3)}"
                f"  rmse {_fmt(result['rpe_rot_rmse_deg'], '°', 3)}",
            ),
        ]
    if "quality" in result:
        from slam.eval.quality_run import format_quality

        rows += format_quality(result["quality"])
    width = max(len(label) for label, _ in rows)
    return "\n".join(f"{label:<{width}}  {value}" for label, value in rows) + "\n"


def _matched(result: dict[str, Any]) -> str:
    """The association line: how many pairs, at whose times, how many poses left out."""
    at = result.get("matched_at", "estimate")
    other = "reference" if at == "estimate" else "estimate"
    return (
        f"{result['matched']} poses at the {at}'s times ({result['excluded']} outside the "
        f"{other}'s time range or in a gap of it)"
    )
