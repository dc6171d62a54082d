"""The one-way dependencies of the architecture, checked on the real import graph."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _modules_loaded_by(package: str) -> set[str]:
    """Import all modules of ``package`` in a fresh interpreter; return loaded top-level names."""
    code = (
        "import importlib, pkgutil, sys\n"
        f"import {package}\n"
        f"for m in pkgutil.walk_packages({package}.__path__, '{package}.'):\n"
        "    importlib.import_module(m.name)\n"
        "print(' '.join(sorted({n.split('.')[0] for n in sys.modules})))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True
    )
    return set(out.stdout.split())


def test_tactile_imports_neither_mujoco_nor_torch():
    loaded = _modules_loaded_by("tactile")
    assert not loaded & {"mujoco", "torch", "sim", "learn"}, loaded & {"mujoco", "torch"}


def test_learn_never_imports_sim():
    source = "\n".join(p.read_text() for p in (ROOT / "learn").rglob("*.py"))
    assert "import sim" not in source and "from sim" not in source


#: Each package's stages in the order of the data's journey; a module imports only its own
#: stage's modules and earlier stages' ("base": the package's top-level modules, first).
STAGES = {
    "learn": ("base", "models", "data", "train", "infer", "evaluate", "classical", "cli"),
    "sim": ("base", "skin", "contactors", "episode", "generate", "warp", "view", "cli"),
    "tactile": ("base", "geometry", "images", "figures", "dataset", "prints", "cli"),
}


def _imports(package: str) -> dict[str, set[str]]:
    """Module name -> the modules of ``package`` it imports anywhere (top level or in
    functions)."""
    import ast

    files = {
        ".".join(path.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__"): path
        for path in (ROOT / package).rglob("*.py")
    }
    graph = {}
    for name, path in files.items():
        found = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                mods = [f"{node.module}.{a.name}" for a in node.names]
                # ``from pkg import module`` names the module, not the package's facade
                mods += [node.module] if not set(mods) <= set(files) else []
            elif isinstance(node, ast.Import):
                mods = [a.name for a in node.names]
            else:
                continue
            found |= {m for m in mods if m.split(".")[0] == package}
        graph[name] = found
    return graph


def _stage(module: str) -> int:
    package, *parts = module.split(".")
    stages = STAGES[package]
    if not parts:
        return len(stages)  # the package's facade (tactile's public names) sits above it all
    inner = parts[0] if parts else "base"
    return stages.index(inner if inner in stages else "base")


@pytest.mark.parametrize("package", sorted(STAGES))
def test_stages_import_one_way(package):
    """No module imports a later stage's (so the stages hold no import cycle); every
    subpackage is a known stage."""
    graph = _imports(package)
    subpackages = {p.name for p in (ROOT / package).iterdir() if (p / "__init__.py").is_file()}
    assert subpackages <= set(STAGES[package]), subpackages - set(STAGES[package])
    known = set(graph)
    later = {
        m: sorted(d for d in deps if d in known and _stage(d) > _stage(m))
        for m, deps in graph.items()
    }
    assert not {m: d for m, d in later.items() if d}


@pytest.mark.parametrize("package", ["sim", "tactile"])
def test_at_most_twelve_modules_at_the_top(package):
    assert len(list((ROOT / package).glob("*.py"))) <= 12


def test_learn_never_imports_experiments():
    source = "\n".join(p.read_text() for p in (ROOT / "learn").rglob("*.py"))
    assert "import experiments" not in source and "from experiments" not in source
