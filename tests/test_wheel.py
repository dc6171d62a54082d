"""The package as a user installs it (``pip install .``, not editable): the wheel holds every
package and asset, and ``handskin generate`` run from a folder outside the checkout finds them."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("handskin", "tactile", "sim", "learn", "experiments", "assets")


@pytest.fixture(scope="module")
def wheel_site(tmp_path_factory) -> Path:
    """The wheel ``pip wheel .`` builds (isolated, as ``pip install .`` does), unpacked: a
    site-packages folder holding what ``pip install .`` would put there."""
    tmp = tmp_path_factory.mktemp("wheel")
    source = tmp / "source"  # a copy: setuptools writes build/ into the folder it builds
    top = {"build", "data", "out", "runs", "reports", ".git"}  # the user's and git's, not ours
    shutil.copytree(
        ROOT,
        source,
        ignore=lambda folder, names: [
            n for n in names if (Path(folder) == ROOT and n in top) or n == "__pycache__"
        ],
    )
    build = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(tmp), str(source)],
        capture_output=True,
        text=True,
    )
    if build.returncode and "No matching distribution found for setuptools" in build.stderr:
        pytest.skip("pip cannot reach a package index to build the wheel (setuptools)")
    assert build.returncode == 0, build.stderr
    (whl,) = tmp.glob("handskin-*.whl")
    site = tmp / "site"
    zipfile.ZipFile(whl).extractall(site)
    return site


def test_the_wheel_holds_every_package_and_asset(wheel_site):
    for pkg in PACKAGES:
        ours = {p.relative_to(ROOT) for p in (ROOT / pkg).rglob("*.py")}
        theirs = {p.relative_to(wheel_site) for p in (wheel_site / pkg).rglob("*.py")}
        assert ours <= theirs, f"the wheel lacks {sorted(ours - theirs)[:5]}"
    assets = {
        p.relative_to(ROOT)
        for p in (ROOT / "assets").rglob("*")
        if p.suffix in {".xml", ".stl", ".obj", ".npz", ".md"}
    }
    assert assets and assets <= {p.relative_to(wheel_site) for p in wheel_site.rglob("*")}


def test_generate_runs_from_the_wheel_outside_the_checkout(wheel_site, tmp_path):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    env = {**os.environ, "PYTHONPATH": str(wheel_site)}
    code = (
        "import sys, sim, tactile, handskin\n"
        f"site = {str(wheel_site)!r}\n"
        "assert all(m.__file__.startswith(site) for m in (sim, tactile, handskin))\n"
        "from handskin.cli import main\n"
        "sys.argv = ['handskin', 'generate', '--n', '20', '--out', 'OUT', '--no-progress']\n"
        "main()\n"
    )
    res = subprocess.run(
        [sys.executable, "-c", code], cwd=elsewhere, env=env, capture_output=True, text=True
    )
    assert res.returncode == 0, res.stderr[-2000:]
    info = json.loads((elsewhere / "OUT" / "info.json").read_text())
    assert info["n_samples"] == 20, info.get("n_samples")
