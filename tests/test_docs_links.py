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


COMMAND = re.compile(r"^\s*handskin ((?:experiment )?[a-z0-9-]+)(.*)$", re.M)


def code_of(text: str) -> str:
    """The page's code: fenced blocks (continued lines joined) and inline code spans, one per
    line."""
    blocks = [m.group(0).strip("`") for m in FENCE.finditer(text)]
    spans = re.findall(r"`([^`\n]+)`", FENCE.sub("", text))
    return "\n".join(blocks + spans).replace("\\\n", " ").replace("&&", "\n")


def _flags(command: str) -> set[str]:
    """Every option name of ``handskin <command>`` (both halves of --x/--no-x)."""
    import typer.main

    from handskin.cli import app

    node = typer.main.get_command(app)
    for word in command.split():
        node = node.commands[word]  # type: ignore[attr-defined]
    return {name for p in node.params for name in (*p.opts, *p.secondary_opts)}


REPORTS = sorted((ROOT / "reports").rglob("*.md"))


@pytest.mark.parametrize("page", PAGES + REPORTS, ids=lambda p: str(p.relative_to(ROOT)))
def test_commands_in_the_docs_use_real_options(page: Path):
    """Every ``handskin <command> ... --option`` written in a page names an option the command
    has (a renamed or removed flag left in the docs fails here)."""
    wrong = []
    for command, rest in COMMAND.findall(code_of(page.read_text())):
        try:
            known = _flags(command)
        except KeyError:
            wrong.append(f"handskin {command}: no such command")
            continue
        used = set(re.findall(r"(?<![\w-])(--[a-z][a-z0-9-]*)", rest.split("#")[0]))
        wrong += [f"handskin {command} {flag}" for flag in sorted(used - known)]
    assert not wrong, f"{page.name}: {wrong}"
