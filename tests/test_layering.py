"""The one-way dependencies of the architecture, checked on the real import graph."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

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


#: learn/'s stages in the order of the data's journey; a module imports only its own stage's
#: modules and earlier stages' (the top-level modules config, inputs, numerics and metrics first).
LEARN_STAGES = ("base", "models", "data", "train", "infer", "evaluate", "classical", "cli")


def _learn_imports() -> dict[str, set[str]]:
    """learn module name -> the learn modules it imports anywhere (top level or in functions)."""
    import ast

    graph = {}
    for path in (ROOT / "learn").rglob("*.py"):
        name = ".".join(path.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__")
        found = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                mods = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
            elif isinstance(node, ast.Import):
                mods = [a.name for a in node.names]
            else:
                continue
            found |= {m for m in mods if m.split(".")[0] == "learn"}
        graph[name] = found
    return graph


def _stage(module: str) -> int:
    parts = module.split(".")
    inner = parts[1] if len(parts) > 1 else "base"
    return LEARN_STAGES.index(inner if inner in LEARN_STAGES else "base")


def test_learn_stages_import_one_way():
    """No learn module imports a later stage's (so the stages hold no import cycle)."""
    graph = _learn_imports()
    known = set(graph)
    later = {
        m: sorted(d for d in deps if d in known and _stage(d) > _stage(m))
        for m, deps in graph.items()
    }
    assert not {m: d for m, d in later.items() if d}


def test_learn_never_imports_experiments():
    source = "\n".join(p.read_text() for p in (ROOT / "learn").rglob("*.py"))
    assert "import experiments" not in source and "from experiments" not in source
