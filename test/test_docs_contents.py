"""docs/robot.md's contents list is its headings, in order, each linked to its anchor."""

from __future__ import annotations

import re
from pathlib import Path

ROBOT_MD = Path(__file__).resolve().parents[1] / "docs" / "robot.md"


def headings(text: str) -> list[tuple[int, str]]:
    """(level, title) of every ``##``-or-deeper heading outside a fenced block."""
    out, fenced = [], False
    for line in text.splitlines():
        if line.startswith("```"):
            fenced = not fenced
        elif not fenced and (m := re.match(r"^(##+) (.*)$", line)):
            out.append((len(m.group(1)), m.group(2)))
    return out


def anchor(title: str, seen: dict[str, int]) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces as hyphens, a
    repeated one numbered."""
    slug = re.sub(r"[^\w\- ]", "", title.strip().lower()).replace(" ", "-")
    n = seen.get(slug, 0)
    seen[slug] = n + 1
    return slug if n == 0 else f"{slug}-{n}"


def contents(text: str) -> list[str]:
    """The list before the first heading: its lines."""
    head = text.split("\n## ", 1)[0]
    return [line for line in head.splitlines() if line.lstrip().startswith("- [")]


def test_the_contents_are_the_headings_in_order():
    text = ROBOT_MD.read_text()
    seen: dict[str, int] = {}
    expected = [
        "  " * (level - 2) + f"- [{title}](#{anchor(title, seen)})"
        for level, title in headings(text)
    ]
    assert len(expected) > 10
    assert contents(text) == expected


def test_an_anchor_drops_punctuation_and_numbers_a_repeat():
    seen: dict[str, int] = {}
    assert anchor("A robot's clock", seen) == "a-robots-clock"
    assert anchor("A 1 kHz driver (T = 1 ms)", seen) == "a-1-khz-driver-t--1-ms"
    assert anchor("A robot's clock", seen) == "a-robots-clock-1"
