"""The `handskin` command: help on every subcommand (at most 50 lines at 100 columns), the map
command on good and bad input."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from handskin.cli import app
from tactile.geometry.synthetic import cylinder_sector_layout
from tactile.images.tactile_map import TactileMap

runner = CliRunner()


def _commands() -> list[str]:
    import typer.main

    return sorted(typer.main.get_command(app).commands)  # type: ignore[attr-defined]


@pytest.mark.parametrize("name", _commands())
def test_every_subcommand_has_help_of_at_most_50_lines(name: str):
    """As ``COLUMNS=100 handskin NAME --help | wc -l`` counts them."""
    result = runner.invoke(app, [name, "--help"], env={"COLUMNS": "100"})
    assert result.exit_code == 0, result.output
    assert "Usage" in result.output
    assert len(result.output.splitlines()) <= 50, result.output


def test_map_builds_the_default_layout_and_writes_a_picture(tmp_path: Path):
    png, npz = tmp_path / "map.png", tmp_path / "m.npz"
    result = runner.invoke(app, ["map", "--png", str(png), "--out", str(npz)])
    assert result.exit_code == 0, result.output
    assert "n_flipped" in result.output and "image" in result.output
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert TactileMap.load(npz).n_taxels == cylinder_sector_layout()[0].n_taxels


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--step-mm", "0"], "--step-mm 0.0 is out of range; allowed > 0 mm/pixel"),
        (["--units", "cm"], "--units 'cm' unknown; choose m or mm"),
    ],
)
def test_map_names_the_bad_flag(args: list[str], message: str):
    result = runner.invoke(app, ["map", *args])
    assert result.exit_code == 2 and message in result.output, result.output


def test_map_reports_a_bad_layout_and_exits_2(tmp_path: Path):
    bad = tmp_path / "bad.txt"
    bad.write_text("0 0 0\n1 0 0\n")
    result = runner.invoke(app, ["map", str(bad)])
    assert result.exit_code == 2
    assert "--units m or mm" in " ".join(result.output.split())


@pytest.mark.parametrize(
    ("command", "option"),
    [("part", None), ("generate", "--part"), ("view", "--part"), ("experiment", "--part")],
)
def test_part_help_names_every_built_in_part(command: str, option: str | None):
    """The part lists in help texts are typed out (importing sim.skin.parts would slow --help); they
    must name every part the registry builds."""
    import re

    import typer.main

    from sim.skin.parts import PARTS

    group = typer.main.get_command(app)
    cmd = group.commands[command]  # type: ignore[attr-defined]
    if command == "experiment":
        cmd = cmd.commands["fidelity"]
    (param,) = [p for p in cmd.params if (option in p.opts if option else p.name == "name")]
    text = " ".join(param.help.split())
    missing = sorted(set(PARTS) - set(re.findall(r"\w+", text)))
    assert not missing, f"{command} help lacks parts {missing}: {text!r}"
