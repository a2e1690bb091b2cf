"""Small line charts drawn with OpenCV (no matplotlib): the figures of ``slam grid study``.

:func:`line_chart` draws one panel — axes, ticks, labelled series with markers, a legend — into
a BGR image; :func:`legend_strip` draws one legend for several panels; :func:`side_by_side`
joins panels. Writing the PNG is the caller's job (through
:mod:`slam.io.atomic`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

PALETTE_BGR: tuple[tuple[int, int, int], ...] = (
    (180, 119, 31),
    (14, 127, 255),
    (44, 160, 44),
    (40, 39, 214),
    (189, 103, 148),
    (75, 86, 140),
)
"""Series colours (BGR), the usual categorical palette."""

FONT = cv2.FONT_HERSHEY_SIMPLEX


@dataclass(frozen=True)
class Series:
    """One line of a chart; ``nan`` values leave gaps."""

    label: str
    x: Sequence[float]
    y: Sequence[float]


def _nice_ticks(lo: float, hi: float, count: int = 6) -> list[float]:
    if not hi > lo:
        hi = lo + 1.0
    raw = (hi - lo) / count
    magnitude = 10 ** math.floor(math.log10(raw))
    step = next(m * magnitude for m in (1, 2, 5, 10) if m * magnitude >= raw)
    start = math.floor(lo / step) * step
    ticks = []
    t = start
    while t <= hi + 1e-9 * step:
        ticks.append(round(t, 10))
        t += step
    return ticks


def _text(
    img: np.ndarray, text: str, org: tuple[int, int], scale: float = 0.45, align: str = "left"
) -> None:
    (w, h), _ = cv2.getTextSize(text, FONT, scale, 1)
    x, y = org
    if align == "center":
        x -= w // 2
    elif align == "right":
        x -= w
    cv2.putText(img, text, (x, y + h // 2), FONT, scale, (0, 0, 0), 1, cv2.LINE_AA)


def line_chart(
    series: Sequence[Series],
    title: str,
    x_label: str,
    y_label: str,
    size: tuple[int, int] = (560, 420),
    log_x: bool = False,
    y_range: tuple[float, float] | None = None,
    legend: bool = True,
) -> np.ndarray:
    """One chart panel as a ``(height, width, 3)`` uint8 BGR image (legend top right)."""
    width, height = size
    img = np.full((height, width, 3), 255, np.uint8)
    left, right, top, bottom = 70, 20, 40, 60
    xs = [float(v) for s in series for v in s.x]
    ys = [float(v) for s in series for v in s.y if np.isfinite(v)]
    fx = (lambda v: math.log10(v)) if log_x else (lambda v: v)
    x_lo, x_hi = (fx(min(xs)), fx(max(xs))) if xs else (0.0, 1.0)
    if x_hi <= x_lo:
        x_hi = x_lo + 1.0
    if y_range is not None:
        y_lo, y_hi = y_range
    else:
        y_lo, y_hi = (0.0, max(ys) * 1.1) if ys else (0.0, 1.0)
        y_lo = min(y_lo, min(ys)) if ys else y_lo
    if y_hi <= y_lo:
        y_hi = y_lo + 1.0
    pw, ph = width - left - right, height - top - bottom

    def px(x: float) -> int:
        return int(round(left + (fx(x) - x_lo) / (x_hi - x_lo) * pw))

    def py(y: float) -> int:
        return int(round(top + ph - (y - y_lo) / (y_hi - y_lo) * ph))

    for t in _nice_ticks(y_lo, y_hi):
        if y_lo - 1e-9 <= t <= y_hi + 1e-9:
            cv2.line(img, (left, py(t)), (left + pw, py(t)), (225, 225, 225), 1)
            _text(img, f"{t:g}", (left - 6, py(t)), align="right")
    x_ticks = sorted(set(xs)) if log_x else _nice_ticks(x_lo, x_hi)
    for t in x_ticks:
        cv2.line(img, (px(t), top + ph), (px(t), top + ph + 5), (0, 0, 0), 1)
        _text(img, f"{t:g}", (px(t), top + ph + 16), align="center")
    cv2.rectangle(img, (left, top), (left + pw, top + ph), (0, 0, 0), 1)
    _text(img, title, (left + pw // 2, 16), scale=0.55, align="center")
    _text(img, x_label, (left + pw // 2, height - 16), align="center")
    (tw, th), _ = cv2.getTextSize(y_label, FONT, 0.45, 1)
    label = np.full((th + 8, tw + 4, 3), 255, np.uint8)
    cv2.putText(label, y_label, (2, th + 2), FONT, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
    label = cv2.rotate(label, cv2.ROTATE_90_COUNTERCLOCKWISE)
    y0 = max(0, top + ph // 2 - label.shape[0] // 2)
    img[y0 : y0 + label.shape[0], 4 : 4 + label.shape[1]] = label[: height - y0]
    for i, s in enumerate(series):
        colour = PALETTE_BGR[i % len(PALETTE_BGR)]
        points = [
            (px(float(x)), py(float(y))) for x, y in zip(s.x, s.y, strict=True) if np.isfinite(y)
        ]
        for a, b in zip(points, points[1:], strict=False):
            cv2.line(img, a, b, colour, 2, cv2.LINE_AA)
        for p in points:
            cv2.circle(img, p, 4, colour, -1, cv2.LINE_AA)
    if legend:
        widths = [cv2.getTextSize(s.label, FONT, 0.45, 1)[0][0] for s in series]
        box_w, box_h = max(widths) + 54, 18 * len(series) + 8
        x0, y0 = left + pw - box_w - 8, top + 8
        cv2.rectangle(img, (x0, y0), (x0 + box_w, y0 + box_h), (255, 255, 255), -1)
        cv2.rectangle(img, (x0, y0), (x0 + box_w, y0 + box_h), (160, 160, 160), 1)
        for i, s in enumerate(series):
            colour = PALETTE_BGR[i % len(PALETTE_BGR)]
            ly = y0 + 13 + 18 * i
            cv2.line(img, (x0 + 8, ly), (x0 + 36, ly), colour, 2, cv2.LINE_AA)
            _text(img, s.label, (x0 + 44, ly))
    return img


def legend_strip(labels: Sequence[str], width: int, height: int = 32) -> np.ndarray:
    """A horizontal legend (series colours in order) to put above a group of panels."""
    img = np.full((height, width, 3), 255, np.uint8)
    x = 16
    for i, label in enumerate(labels):
        colour = PALETTE_BGR[i % len(PALETTE_BGR)]
        cv2.line(img, (x, height // 2), (x + 28, height // 2), colour, 2, cv2.LINE_AA)
        cv2.circle(img, (x + 14, height // 2), 4, colour, -1, cv2.LINE_AA)
        _text(img, label, (x + 36, height // 2))
        x += 36 + cv2.getTextSize(label, FONT, 0.45, 1)[0][0] + 28
    return img


def side_by_side(panels: Sequence[np.ndarray]) -> np.ndarray:
    """Panels of equal height joined left to right."""
    return np.concatenate(list(panels), axis=1)
