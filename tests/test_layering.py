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
