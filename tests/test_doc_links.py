"""Every link between the project's Markdown pages reaches a file, and every ``#anchor`` a heading.

The README and ``docs/`` cross-reference each other by section (``docs/slam.md#smoothing-...``);
a heading renamed or moved would leave such a link pointing nowhere, and GitHub shows no error,
only the top of the page. Anchors are GitHub's: the heading's text lower-cased, what is not a
letter, digit, space, hyphen or underscore dropped, spaces made hyphens, repeats numbered ``-1``,
``-2``.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
LINK = re.compile(r"\[(?:[^\]\[]|\[[^\]]*\])*\]\(([^()\s]+)\)")
"""A Markdown link ``[text](target)`` (the text may hold one level of brackets)."""
FENCE = re.compile(r"^(```|~~~)")


def slug(heading: str) -> str:
    """GitHub's anchor of a heading's text (before numbering repeats)."""
    text = re.sub(r"<[^>]+>", "", heading).strip().lower()
    text = "".join(c for c in text if c.isalnum() or c in " -_")
    return text.replace(" ", "-")


def _lines_outside_code(text: str) -> list[str]:
    lines, fenced = [], False
    for line in text.splitlines():
        if FENCE.match(line.strip()):
            fenced = not fenced
            continue
        if not fenced:
            lines.append(line)
    return lines


def anchors(path: Path) -> set[str]:
    """Every anchor of a page's headings, repeats numbered as GitHub numbers them."""
    seen: dict[str, int] = {}
    out = set()
    for line in _lines_outside_code(path.read_text(encoding="utf-8")):
        m = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if not m:
            continue
        base = slug(m.group(1))
        n = seen.get(base, 0)
        seen[base] = n + 1
        out.add(base if n == 0 else f"{base}-{n}")
    return out


def links(path: Path) -> list[tuple[int, str]]:
    """``(line number, target)`` of every relative link of a page, code blocks and inline code
    left out."""
    found = []
    fenced = False
    for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        if FENCE.match(line.strip()):
            fenced = not fenced
            continue
        if fenced:
            continue
        for target in LINK.findall(re.sub(r"`[^`]*`", "", line)):
            if not re.match(r"^[a-z]+:", target):  # http:, https:, mailto: are not ours
                found.append((number, target))
    return found


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_link_reaches_its_file_and_heading(page):
    cache: dict[Path, set[str]] = {}
    broken = []
    for number, target in links(page):
        file_part, _, anchor = target.partition("#")
        dest = (page.parent / file_part).resolve() if file_part else page
        where = f"{page.relative_to(ROOT)}:{number}: {target}"
        if not dest.exists():
            broken.append(f"{where} (no such file)")
            continue
        if anchor and dest.suffix == ".md":
            if dest not in cache:
                cache[dest] = anchors(dest)
            if anchor not in cache[dest]:
                broken.append(f"{where} (no such heading in {dest.name})")
    assert not broken, "\n".join(broken)


def test_the_slug_is_githubs():
    assert slug("`classic` — the ECE276A method, faithfully") == (
        "classic--the-ece276a-method-faithfully"
    )
    assert slug("How far to trust the odometry's shape (default, measured)") == (
        "how-far-to-trust-the-odometrys-shape-default-measured"
    )
    assert slug("fr-clinic's long corridor at 2000–2060 s") == (
        "fr-clinics-long-corridor-at-20002060-s"
    )


def test_a_link_to_a_missing_heading_is_found(tmp_path):
    (tmp_path / "a.md").write_text("# Top\n## Two words\n## Two words\n", encoding="utf-8")
    page = tmp_path / "b.md"
    page.write_text(
        "[ok](a.md#two-words) [again](a.md#two-words-1) [bad](a.md#three)\n"
        "```\n[in code](a.md#nowhere)\n```\n`[inline](a.md#nowhere)` [web](https://x.org/#y)\n",
        encoding="utf-8",
    )
    assert anchors(tmp_path / "a.md") == {"top", "two-words", "two-words-1"}
    assert links(page) == [(1, "a.md#two-words"), (1, "a.md#two-words-1"), (1, "a.md#three")]
