"""The `handskin` command: help on every subcommand, the map command on good and bad input."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from handskin.cli import app

runner = CliRunner()


def _commands() -> list[str]:
    import typer.main

    return sorted(typer.main.get_command(app).commands)  # type: ignore[attr-defined]


@pytest.mark.parametrize("name", _commands())
def test_every_subcommand_has_help(name: str):
    result = runner.invoke(app, [name, "--help"])
    assert result.exit_code == 0, result.output
    assert "Usage" in result.output


def test_map_builds_the_default_layout_and_writes_a_picture(tmp_path: Path):
    png = tmp_path / "map.png"
    result = runner.invoke(app, ["map", "--png", str(png), "--save", str(tmp_path / "m.npz")])
    assert result.exit_code == 0, result.output
    assert "n_flipped" in result.output and "image" in result.output
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and (tmp_path / "m.npz").exists()


def test_map_reports_a_bad_layout_and_exits_2(tmp_path: Path):
    bad = tmp_path / "bad.txt"
    bad.write_text("0 0 0\n1 0 0\n")
    result = runner.invoke(app, ["map", str(bad)])
    assert result.exit_code == 2
    assert "units" in result.output


@pytest.mark.parametrize(
    ("command", "option"),
    [("part", None), ("generate", "--part"), ("view", "--part"), ("experiment", "--part")],
)
def test_part_help_names_every_built_in_part(command: str, option: str | None):
    """The part lists in help texts are typed out (importing sim.parts would slow --help); they
    must name every part the registry builds."""
    import re

    import typer.main

    from sim.parts import PARTS

    group = typer.main.get_command(app)
    cmd = group.commands[command]  # type: ignore[attr-defined]
    if command == "experiment":
        cmd = cmd.commands["fidelity"]
    (param,) = [p for p in cmd.params if (option in p.opts if option else p.name == "name")]
    text = " ".join(param.help.split())
    missing = sorted(set(PARTS) - set(re.findall(r"\w+", text)))
    assert not missing, f"{command} help lacks parts {missing}: {text!r}"
