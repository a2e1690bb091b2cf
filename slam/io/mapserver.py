"""ROS map_server / nav2 maps: ``map.yaml`` + ``map.pgm``, written and read back.

This module owns the map_server file format as ``map_saver`` writes it and ``map_server`` /
nav2's ``map_io`` read it:

* ``map.pgm``: binary PGM (``P5``, maxval 255), the image's top row is the largest y. In
  trinary mode a cell is 0 (occupied), 254 (free) or 205 (unknown), the values ``map_saver``
  writes.
* ``map.yaml``: ``image``, ``mode`` (``trinary``), ``resolution`` (m per cell), ``origin``
  ``[x, y, yaw]`` (the pose of the lower-left corner of the lower-left cell), ``negate`` (0),
  ``occupied_thresh`` (0.65), ``free_thresh`` (0.196).

Reading applies map_server's rule: a pixel of value ``v`` has occupancy ``p = (255 − v) / 255``
(``v / 255`` with ``negate: 1``); ``p > occupied_thresh`` is occupied, ``p < free_thresh`` free,
anything else unknown (``scale`` mode: in between, ``99·(p − free)/(occ − free)``).
Writing thresholds the occupancy probability of the log-odds the same way, so a map read back
equals the thresholded log-odds cell for cell.

PyYAML is not a dependency: :func:`parse_map_yaml` is a small reader of the YAML that
map_server's files are written in (``key: value`` lines or one ``{key: value, ...}`` flow
mapping, ``origin`` as ``[x, y, yaw]`` or ``- value`` lines), with errors naming the line and key.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from slam.errors import DataError
from slam.io.atomic import write_files
from slam.io.text import decode_utf8, read_input

if TYPE_CHECKING:
    from collections.abc import Iterator

F64 = NDArray[np.float64]

OCCUPIED_THRESH = 0.65
"""map_server's default: occupancy above this is an obstacle."""
FREE_THRESH = 0.196
"""map_server's default: occupancy below this is free (205, the unknown grey, is 0.196078)."""
OCCUPIED_PIXEL, FREE_PIXEL, UNKNOWN_PIXEL = 0, 254, 205
"""Pixel values ``map_saver`` writes in trinary mode."""
OCCUPIED, FREE, UNKNOWN = 100, 0, -1
"""Cell values of :attr:`MapServerMap.occupancy` (those of ``nav_msgs/OccupancyGrid``)."""

MODES = ("trinary", "scale")
"""``mode`` values this reader interprets."""
YAW_ZERO = 1e-4
"""An origin yaw within this many radians of 0 is read as 0 (float noise of a map's writer)."""
_KEYS = ("image", "mode", "resolution", "origin", "negate", "occupied_thresh", "free_thresh")
_REQUIRED = ("image", "resolution", "origin", "negate", "occupied_thresh", "free_thresh")


def trinary(
    log_odds: NDArray[np.floating],
    occupied_thresh: float = OCCUPIED_THRESH,
    free_thresh: float = FREE_THRESH,
) -> NDArray[np.int8]:
    """Cells ``(H, W)`` as 100 / 0 / −1 (occupied / free / unknown) from their log-odds: the
    occupancy probability ``1 − 1/(1 + e^l)`` above ``occupied_thresh`` or below
    ``free_thresh``. Rows keep the grid's order (row 0 is the smallest y)."""
    from slam.rowwise import by_rows

    def block(lo: NDArray[np.floating]) -> NDArray[np.int8]:
        p = 1.0 - 1.0 / (1.0 + np.exp(np.asarray(lo, dtype=np.float64)))
        out = np.full(p.shape, UNKNOWN, dtype=np.int8)
        out[p > occupied_thresh] = OCCUPIED
        out[p < free_thresh] = FREE
        return out

    return by_rows(block, np.asarray(log_odds), np.int8)  # temporaries of a block of rows


def pgm_image(occupancy: NDArray[np.int8]) -> NDArray[np.uint8]:
    """The trinary ``map.pgm`` pixels of ``occupancy`` (grid rows, flipped so the top is +y)."""
    image = np.full(occupancy.shape, UNKNOWN_PIXEL, dtype=np.uint8)
    image[occupancy == OCCUPIED] = OCCUPIED_PIXEL
    image[occupancy == FREE] = FREE_PIXEL
    return np.ascontiguousarray(image[::-1])


def pgm_bytes(image: NDArray[np.uint8], resolution: float) -> bytes:
    """A binary PGM (``P5``, maxval 255) of ``image`` with map_saver's comment line."""
    h, w = image.shape
    header = f"P5\n# CREATOR: slam {resolution:.3f} m/pix\n{w} {h}\n255\n".encode("ascii")
    return header + np.ascontiguousarray(image, dtype=np.uint8).tobytes()


def map_yaml_text(
    image: str,
    resolution: float,
    origin: tuple[float, float, float],
    occupied_thresh: float = OCCUPIED_THRESH,
    free_thresh: float = FREE_THRESH,
) -> str:
    """The ``map.yaml`` of a trinary map (floats written so they read back exactly)."""
    x, y, yaw = (float(v) for v in origin)
    plain = re.fullmatch(r"[A-Za-z0-9_./][A-Za-z0-9_./ -]*", image) and not image.endswith(" ")
    if not plain:  # '#' starts a comment, ': ' a mapping...: a double-quoted YAML string
        image = '"' + image.replace("\\", "\\\\").replace('"', '\\"') + '"'
    return (
        f"image: {image}\n"
        f"mode: trinary\n"
        f"resolution: {float(resolution)!r}\n"
        f"origin: [{x!r}, {y!r}, {yaw!r}]\n"
        f"negate: 0\n"
        f"occupied_thresh: {occupied_thresh!r}\n"
        f"free_thresh: {free_thresh!r}\n"
    )


def write_map(
    pgm_path: Path, log_odds: NDArray[np.floating], resolution: float, origin: Any
) -> Path:
    """Write ``pgm_path`` and the ``.yaml`` beside it (same stem) for a log-odds grid.

    Both files are written to temporary siblings first and renamed only when both are complete,
    so neither appears half-written. Returns the yaml path.
    """
    pgm_path = Path(pgm_path)
    yaml_path = pgm_path.with_suffix(".yaml")
    ox, oy = (float(v) for v in np.asarray(origin, dtype=np.float64)[:2])
    image = pgm_image(trinary(log_odds))
    write_files(
        {
            pgm_path: pgm_bytes(image, resolution),
            yaml_path: map_yaml_text(pgm_path.name, resolution, (ox, oy, 0.0)).encode("utf-8"),
        }
    )
    return yaml_path


# --- reading ------------------------------------------------------------------------------


@dataclass(frozen=True)
class MapServerMap:
    """A map read from ``map.yaml``: occupancy per cell in the grid convention of
    :class:`slam.mapping.OccupancyGrid` (``occupancy[iy, ix]``, row 0 the smallest y)."""

    yaml_path: Path
    image_path: Path
    resolution: float
    origin: F64
    """``(3,)`` pose ``(x, y, yaw)`` of the lower-left corner of cell ``(0, 0)``."""
    occupancy: NDArray[np.int8]
    """``(H, W)``: 100 occupied, 0 free, −1 unknown (``scale`` mode: 1..99 in between)."""
    mode: str
    negate: int
    occupied_thresh: float
    free_thresh: float

    @property
    def shape(self) -> tuple[int, int]:
        """``(rows, columns)``."""
        return self.occupancy.shape  # type: ignore[return-value]

    def occupied(self) -> NDArray[np.bool_]:
        """Obstacle cells."""
        return self.occupancy == OCCUPIED

    def free(self) -> NDArray[np.bool_]:
        """Free cells."""
        return self.occupancy == FREE

    def unknown(self) -> NDArray[np.bool_]:
        """Cells neither free nor occupied."""
        return self.occupancy == UNKNOWN

    def world_to_cell(self, xy: Any) -> NDArray[np.int64]:
        """Cell indices ``(..., 2)`` as ``(ix, iy)`` of world points ``(..., 2)``."""
        xy = np.asarray(xy, dtype=np.float64)
        c, s = math.cos(self.origin[2]), math.sin(self.origin[2])
        dx, dy = xy[..., 0] - self.origin[0], xy[..., 1] - self.origin[1]
        local = np.stack([c * dx + s * dy, -s * dx + c * dy], axis=-1)
        return np.floor(local / self.resolution).astype(np.int64)

    def cell_center(self, ix: Any, iy: Any) -> F64:
        """World ``(x, y)`` of the centre of cell ``(ix, iy)``."""
        lx = (np.asarray(ix, dtype=np.float64) + 0.5) * self.resolution
        ly = (np.asarray(iy, dtype=np.float64) + 0.5) * self.resolution
        c, s = math.cos(self.origin[2]), math.sin(self.origin[2])
        return np.stack([self.origin[0] + c * lx - s * ly, self.origin[1] + s * lx + c * ly], -1)

    def summary(self) -> dict[str, Any]:
        """Size, resolution, origin and cell counts (what ``slam eval`` reports)."""
        return {
            "yaml": str(self.yaml_path),
            "shape": list(self.shape),
            "resolution": self.resolution,
            "origin": [float(v) for v in self.origin],
            "occupied_cells": int(np.count_nonzero(self.occupied())),
            "free_cells": int(np.count_nonzero(self.free())),
            "unknown_cells": int(np.count_nonzero(self.unknown())),
        }


def read_map_yaml(path: Path) -> MapServerMap:
    """Read a map_server ``map.yaml`` and its image; :class:`DataError` naming file, line and key
    when either is malformed."""
    path = Path(path)
    raw = read_input(
        path, "map file not found", "is a folder, expected a map_server map.yaml", "cannot read"
    )
    values = parse_map_yaml(decode_utf8(path, raw), str(path))
    image_path = Path(values["image"])
    if not image_path.is_absolute():
        image_path = path.parent / image_path
    image = read_map_image(image_path)
    occupancy = _occupancy(image, values)
    return MapServerMap(
        yaml_path=path,
        image_path=image_path,
        resolution=values["resolution"],
        origin=np.asarray(values["origin"], dtype=np.float64),
        occupancy=np.ascontiguousarray(occupancy[::-1]),
        mode=values["mode"],
        negate=values["negate"],
        occupied_thresh=values["occupied_thresh"],
        free_thresh=values["free_thresh"],
    )


def _occupancy(image: NDArray[np.uint8], values: dict[str, Any]) -> NDArray[np.int8]:
    """map_server's pixel rule (image rows, top first)."""
    v = image.astype(np.float64)
    p = v / 255.0 if values["negate"] else (255.0 - v) / 255.0
    occ, free = values["occupied_thresh"], values["free_thresh"]
    out = np.full(image.shape, UNKNOWN, dtype=np.int8)
    if values["mode"] == "scale":
        between = (p >= free) & (p <= occ)
        out[between] = np.rint(99.0 * (p[between] - free) / (occ - free)).astype(np.int8)
    out[p > occ] = OCCUPIED
    out[p < free] = FREE
    return out


def read_map_image(path: Path) -> NDArray[np.uint8]:
    """The image of a map as ``(H, W)`` uint8, top row first: PGM (``P5``/``P2``) read here,
    other formats (PNG) through OpenCV with channels averaged as map_server does."""
    raw = read_input(path, "map image not found", None, "cannot read map image")
    if raw[:2] in (b"P5", b"P2"):
        return _parse_pgm(path, raw)
    import cv2

    try:  # OpenCV asserts on an empty buffer
        image = cv2.imdecode(np.frombuffer(raw, np.uint8), cv2.IMREAD_UNCHANGED) if raw else None
    except cv2.error:
        image = None
    if image is None:
        empty = " (the file is empty)" if not raw else ""
        raise DataError(f"{path}: not a PGM or an image OpenCV can read{empty}")
    if image.dtype != np.uint8:
        raise DataError(f"{path}: expected an 8-bit image, found {image.dtype}")
    if image.ndim == 3:
        colour = image[:, :, :3] if image.shape[2] >= 3 else image[:, :, :1]
        image = np.rint(colour.astype(np.float64).mean(axis=2)).astype(np.uint8)
    return image


def _parse_pgm(path: Path, raw: bytes) -> NDArray[np.uint8]:
    """``P5`` (binary) or ``P2`` (ASCII) PGM with maxval ≤ 255."""
    fields: list[bytes] = []
    pos = 2
    while len(fields) < 3:
        while pos < len(raw) and raw[pos : pos + 1].isspace():
            pos += 1
        if pos < len(raw) and raw[pos : pos + 1] == b"#":
            end = raw.find(b"\n", pos)
            pos = len(raw) if end < 0 else end + 1
            continue
        start = pos
        while pos < len(raw) and not raw[pos : pos + 1].isspace():
            pos += 1
        if start == pos:
            raise DataError(f"{path}: PGM header ends early (expected width, height, maxval)")
        fields.append(raw[start:pos])
    try:
        width, height, maxval = (int(f) for f in fields)
    except ValueError:
        raise DataError(f"{path}: PGM header: expected integers, found {fields!r}") from None
    if width < 1 or height < 1 or not 1 <= maxval <= 255:
        raise DataError(
            f"{path}: PGM header: expected width, height ≥ 1 and maxval 1..255, "
            f"found {width} {height} {maxval}"
        )
    if raw[:2] == b"P2":
        values = raw[pos:].split()
        if len(values) != width * height:
            raise DataError(f"{path}: expected {width * height} pixel values, found {len(values)}")
        data = np.array([int(v) for v in values], dtype=np.int64)
    else:
        data = np.frombuffer(raw, np.uint8, offset=pos + 1)  # one whitespace after maxval
        if data.size != width * height:
            raise DataError(
                f"{path}: expected {width * height} pixel bytes ({width}×{height}), "
                f"found {data.size}"
            )
    if maxval != 255:
        data = np.rint(data * (255.0 / maxval))
    return data.astype(np.uint8).reshape(height, width)


def parse_map_yaml(text: str, source: str = "map.yaml") -> dict[str, Any]:
    """The keys of a map_server yaml, validated.

    Reads the YAML map_server / nav2 / slam_toolbox / GMapping files are written in: a mapping of
    ``key: value`` lines or one ``{key: value, ...}`` flow mapping (which may span lines), ``#``
    comments, a leading byte-order mark, ``origin`` as a flow list ``[x, y, yaw]`` or as
    ``- value`` lines below the key. Keys other than map_server's are ignored, as map_server
    ignores them (with any block below them). A repeated, missing or malformed key, or a file
    that is not a mapping, is a :class:`DataError` naming the line. Returns ``image`` (str),
    ``mode`` (default ``trinary``), ``resolution``, ``origin`` (3 floats; a yaw within
    :data:`YAW_ZERO` of 0 is 0), ``negate`` (0/1), ``occupied_thresh``, ``free_thresh``.
    """
    lines = []
    for lineno, line in enumerate(text.removeprefix("\ufeff").splitlines(), start=1):
        body = _strip_comment(line).rstrip()
        if body.strip() and body.strip() not in ("---", "..."):
            lines.append((lineno, body))
    if lines and lines[0][1].startswith("{"):
        entries = _flow_entries(lines, source)
    else:
        entries = _block_entries(lines, source)
    values: dict[str, Any] = {}
    seen: set[str] = set()
    for lineno, key, raw, block in entries:
        where = f"{source}:{lineno}"
        if key in seen:
            raise DataError(f"{where}: {key} is given twice")
        seen.add(key)
        if key not in _KEYS:
            continue  # map_server ignores keys it does not know
        if key == "origin" and not raw and block:
            values[key] = _origin_lines(block, source, lineno)
        elif block:
            found = block[0][1].strip()
            raise DataError(
                f"{source}:{block[0][0]}: {key}: expected a value on the key's line, "
                f"found the indented {found!r} below it"
            )
        else:
            values[key] = _value(key, raw, where)
    missing = [k for k in _REQUIRED if k not in values]
    if missing:
        raise DataError(f"{source}: missing key(s) {', '.join(missing)}")
    values.setdefault("mode", "trinary")
    if abs(values["origin"][2]) <= YAW_ZERO:
        values["origin"][2] = 0.0
    if not values["free_thresh"] < values["occupied_thresh"]:
        raise DataError(
            f"{source}: expected free_thresh < occupied_thresh, found "
            f"{values['free_thresh']} and {values['occupied_thresh']}"
        )
    return values


_Line = tuple[int, str]
"""A line's number and its text without comment or trailing blanks."""
_Entry = tuple[int, str, str, list[_Line]]
"""A key's line number, the key, its value on that line and the indented lines below it."""


def _block_entries(lines: list[_Line], source: str) -> list[_Entry]:
    """The ``key: value`` lines of a block mapping; a key with an empty value (or a ``|``/``>``
    block scalar) takes the indented lines below it (and ``- item`` lines at its own indentation,
    PyYAML's style for a list); a ``[``/``{`` value runs on until its brackets close."""
    entries: list[_Entry] = []
    i = 0
    while i < len(lines):
        lineno, body = lines[i]
        where = f"{source}:{lineno}"
        if body == "-" or body.startswith(("- ", "[")):
            raise DataError(
                f"{where}: the file must be a mapping of keys ('key: value' lines), "
                f"found a list ({body.strip()!r})"
            )
        colon = _key_colon(body)
        if body[0].isspace() or body.startswith("{") or colon < 0:
            raise DataError(
                f"{where}: expected a top-level 'key: value' line, found {body.strip()!r}"
            )
        key, raw = _string(body[:colon].strip()), body[colon + 1 :].strip()
        i += 1
        block: list[_Line] = []
        if raw.startswith(("[", "{")) and _depth(raw) > 0:
            joined, i = _balanced(lines, i - 1, raw, f"{where}: {key}")
            raw = " ".join(text for _, text in joined)
        elif not raw or raw[0] in "|>":
            while i < len(lines) and (
                lines[i][1][0].isspace() or (not raw and _is_item(lines[i][1]))
            ):
                block.append(lines[i])
                i += 1
        entries.append((lineno, key, raw, block))
    return entries


def _flow_entries(lines: list[_Line], source: str) -> list[_Entry]:
    """The entries of a top-level ``{key: value, ...}`` mapping (``lines[0]`` starts it); commas
    inside ``[..]``, ``{..}`` or quotes belong to the value."""
    joined, end = _balanced(lines, 0, lines[0][1].strip(), f"{source}:{lines[0][0]}")
    text = "\n".join(part for _, part in joined)

    def line_at(offset: int) -> int:
        return joined[text.count("\n", 0, offset)][0]

    items: list[tuple[int, str]] = []
    start, depth, close = 1, 0, len(text)
    for i, ch in _unquoted(text):
        if ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
        if depth == 0 or (ch == "," and depth == 1):
            items.append((start, text[start:i]))
            start = i + 1
            if depth == 0:
                close = i
                break
    rest = text[close + 1 :].strip()
    if text[close] != "}":
        raise DataError(
            f"{source}:{line_at(close)}: expected '}}' closing the mapping, found {text[close]!r}"
        )
    if rest:
        raise DataError(
            f"{source}:{line_at(close)}: expected nothing after the mapping's '}}', found {rest!r}"
        )
    if end < len(lines):
        raise DataError(
            f"{source}:{lines[end][0]}: expected nothing after the mapping that ends on line "
            f"{line_at(close)}, found {lines[end][1].strip()!r}"
        )
    entries: list[_Entry] = []
    for n, (offset, item) in enumerate(items):
        lead = len(item) - len(item.lstrip())
        item = item.strip()
        where = f"{source}:{line_at(offset + lead)}"
        if not item:
            if n == len(items) - 1:
                continue  # a trailing comma, or {}
            raise DataError(f"{where}: expected 'key: value' between two commas, found nothing")
        colon = _key_colon(item)
        if colon < 0:
            raise DataError(f"{where}: expected 'key: value' in the mapping, found {item!r}")
        raw = item[colon + 1 :].strip().replace("\n", " ")
        entries.append((line_at(offset + lead), _string(item[:colon].strip()), raw, []))
    return entries


def _balanced(lines: list[_Line], i: int, first: str, where: str) -> tuple[list[_Line], int]:
    """``first`` (the rest of ``lines[i]`` from a ``[`` or ``{``) and the lines after it until
    its brackets close, and the index of the next line."""
    joined = [(lines[i][0], first)]
    depth = _depth(first)
    i += 1
    while depth > 0:
        if i == len(lines):
            closing = "]" if first[0] == "[" else "}"
            raise DataError(f"{where}: {first[0]!r} is never closed (expected a {closing!r})")
        joined.append((lines[i][0], lines[i][1].strip()))
        depth += _depth(joined[-1][1])
        i += 1
    return joined, i


def _origin_lines(block: list[_Line], source: str, lineno: int) -> list[float]:
    """``origin`` given as ``- value`` lines below the key."""
    indent = len(block[0][1]) - len(block[0][1].lstrip())
    numbers = []
    for n, body in block:
        item = body.strip()
        if len(body) - len(body.lstrip()) != indent or not _is_item(item):
            raise DataError(
                f"{source}:{n}: origin: expected '- number' lines [x, y, yaw], found {item!r}"
            )
        numbers.append(_number("origin", item[1:].strip(), f"{source}:{n}"))
    if len(numbers) != 3:
        raise DataError(
            f"{source}:{lineno}: origin: expected 3 numbers [x, y, yaw], found {len(numbers)} "
            f"('- ' lines {block[0][0]}..{block[-1][0]})"
        )
    return numbers


def _is_item(text: str) -> bool:
    """``text`` (a line without its indentation) is an item of a block list."""
    return text == "-" or text.startswith("- ")


def _unquoted(text: str) -> Iterator[tuple[int, str]]:
    """``(index, character)`` of ``text`` outside quoted scalars (a quote opens one only where a
    scalar starts: at the start, or after ``[``, ``{``, ``,``, ``:`` or a list's ``-``)."""
    quote, escaped = "", False
    prev, dash = "", False  # the last non-blank character outside quotes; a list's '-'
    for i, ch in enumerate(text):
        if quote:
            if escaped:
                escaped = False
            elif ch == "\\" and quote == '"':
                escaped = True
            elif ch == quote:
                quote, prev, dash = "", ch, False
            continue
        if ch in "'\"" and (not prev or prev in "[{,:" or dash):
            quote = ch
            continue
        if not ch.isspace():
            dash = ch == "-" and (i == 0 or text[i - 1].isspace())
            prev = ch
        yield i, ch


def _depth(text: str) -> int:
    """How many ``[``/``{`` of ``text`` are not closed."""
    depth = 0
    for _, ch in _unquoted(text):
        depth += (ch in "[{") - (ch in "]}")
    return depth


def _key_colon(text: str) -> int:
    """The index of the ``:`` that ends the key of ``text`` (−1: none)."""
    return next((i for i, ch in _unquoted(text) if ch == ":"), -1)


def _strip_comment(line: str) -> str:
    for i, ch in _unquoted(line):
        if ch == "#" and (i == 0 or line[i - 1].isspace()):
            return line[:i]
    return line


def _value(key: str, raw: str, where: str) -> Any:
    if key in ("image", "mode"):
        text = _string(raw)
        if not text:
            raise DataError(f"{where}: {key}: expected a non-empty string, found {raw!r}")
        if key == "mode" and text not in MODES:
            raise DataError(f"{where}: mode: expected one of {', '.join(MODES)}, found {text!r}")
        return text
    if key == "origin":
        if not (raw.startswith("[") and raw.endswith("]")):
            raise DataError(f"{where}: origin: expected [x, y, yaw], found {raw!r}")
        parts = [p.strip() for p in raw[1:-1].split(",")]
        if len(parts) != 3:
            raise DataError(f"{where}: origin: expected 3 numbers [x, y, yaw], found {raw!r}")
        return [_number(key, p, where) for p in parts]
    if key == "negate":  # Nav2 reads an int, else a bool
        value = _string(raw).lower()
        if value not in ("0", "1", "true", "false"):
            raise DataError(f"{where}: negate: expected 0, 1, true or false, found {raw!r}")
        return int(value in ("1", "true"))
    number = _number(key, raw, where)
    if key == "resolution" and not number > 0:
        raise DataError(f"{where}: resolution: expected a positive number of metres, found {raw}")
    if key.endswith("_thresh") and not 0.0 <= number <= 1.0:
        raise DataError(f"{where}: {key}: expected a value in [0, 1], found {raw}")
    return number


def _string(raw: str) -> str:
    """A YAML scalar string: plain, 'single-quoted' (``''`` a quote) or "double-quoted" (``\\"``
    and ``\\\\`` escapes, as :func:`map_yaml_text` writes a name with ``#`` or ``: ``)."""
    if len(raw) >= 2 and raw[0] == raw[-1] == "'":
        return raw[1:-1].replace("''", "'")
    if len(raw) >= 2 and raw[0] == raw[-1] == '"':
        return re.sub(r"\\(.)", r"\1", raw[1:-1])
    return raw


def _number(key: str, raw: str, where: str) -> float:
    try:
        value = float(_string(raw))  # yaml-cpp converts a quoted number too
    except ValueError:
        raise DataError(f"{where}: {key}: expected a number, found {raw!r}") from None
    if not math.isfinite(value):
        raise DataError(f"{where}: {key}: expected a finite number, found {raw!r}")
    return value
