"""Every relative link in the README and in docs/*.md names a file of the repository, and every
``#anchor`` a heading of the file it points to (GitHub's rule for heading ids: lower case,
punctuation dropped, spaces to hyphens). Moving a section between pages is where links break."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
LINK = re.compile(r"\]\(([^)\s]+)\)")
FENCE = re.compile(r"^```.*?^```", re.M | re.S)


def github_anchor(heading: str) -> str:
    """The id GitHub gives a markdown heading: '## HandsNet's speed' -> 'handsnets-speed'."""
    text = re.sub(r"[`*]", "", heading.strip().lower())
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def anchors(page: Path) -> set[str]:
    text = FENCE.sub("", page.read_text())
    return {github_anchor(h) for h in re.findall(r"^#{1,6} (.+)$", text, flags=re.M)}


def test_github_anchor_rule():
    assert github_anchor("HandsNet's speed by machine") == "handsnets-speed-by-machine"
    assert github_anchor("Data, width, flips, averaging, finger spread, shifts") == (
        "data-width-flips-averaging-finger-spread-shifts"
    )
    assert github_anchor("`handskin view` and **forearm_x2**") == "handskin-view-and-forearm_x2"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_resolve(page: Path):
    broken = []
    for target in LINK.findall(FENCE.sub("", page.read_text())):
        if re.match(r"[a-z]+://|mailto:", target):
            continue
        path, _, anchor = target.partition("#")
        dest = (page.parent / path).resolve() if path else page
        if not dest.exists():
            broken.append(f"{target} (no such file)")
        elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
            broken.append(f"{target} (no heading #{anchor} in {dest.name})")
    assert not broken, f"{page.name}: broken links: {broken}"
