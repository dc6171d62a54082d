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


#: Python that makes every import of torch fail as in an environment without it (a finder that
#: refuses it; torch stays out of sys.modules, where SciPy looks for it)
NO_TORCH = """import importlib.abc, sys
class NoTorch(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name.partition(".")[0] == "torch":
            raise ModuleNotFoundError("No module named 'torch'", name="torch")
sys.meta_path.insert(0, NoTorch())
"""


def test_the_readme_main_line_needs_no_torch(tmp_path: Path):
    """The README's first line installs handskin without the learn extra: `handskin`, its help
    and a small `generate` then `sheet` run in a Python where importing torch fails, and a
    command that needs torch says how to install it."""
    import subprocess
    import sys

    def handskin(*args: str) -> subprocess.CompletedProcess:
        code = (
            NO_TORCH
            + "sys.argv = ['handskin', *sys.argv[1:]]\nfrom handskin.cli import main\nmain()"
        )
        return subprocess.run(
            [sys.executable, "-c", code, *args], capture_output=True, text=True, cwd=tmp_path
        )

    for args in (["--help"], ["experiment", "candidates", "--help"], ["train", "--help"]):
        done = handskin(*args)
        assert done.returncode == 0, done.stderr
    done = handskin("generate", "--n", "6", "--out", "out", "--no-progress")
    assert done.returncode == 0, done.stderr
    done = handskin("sheet", "out", "--png", "sheet.png")
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "sheet.png").read_bytes()[:4] == b"\x89PNG"
    done = handskin("train", "out", "--out", "run", "--arch", "handsnet")
    assert done.returncode != 0 and "torch" in done.stderr.lower()
