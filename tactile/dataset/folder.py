"""The names inside a dataset folder, shared by the writer, the merge and the reader.

OUT/manifest.json            what the data was made from (`tactile.dataset.manifest`)
OUT/chunks/static.h5         map, layout, dims and the writer's attrs, written once
OUT/chunks/chunk_000000.h5   samples of chunk 0 (complete chunks only carry this name)
OUT/dataset.h5               the merged dataset (`tactile.dataset.merge`)
OUT/info.json                its sidecar: fields with dtype, shape and unit; counts; splits
"""

from __future__ import annotations

import re
from pathlib import Path

DATASET = "dataset.h5"
INFO = "info.json"
CHUNKS = "chunks"
STATIC = "static.h5"  # chunks/static.h5: map, layout, dims and the caller's attrs, written once
CHUNK_RE = re.compile(r"^chunk_(\d{6})\.h5$")


def chunk_path(folder: str | Path, k: int) -> Path:
    """Path of chunk ``k`` in a dataset folder: ``chunks/chunk_{k:06d}.h5``."""
    return Path(folder) / CHUNKS / f"chunk_{k:06d}.h5"


def list_chunks(folder: str | Path) -> list[int]:
    """Indices of the complete chunks of a dataset folder, sorted (temporary files ignored)."""
    d = Path(folder) / CHUNKS
    if not d.is_dir():
        return []
    return sorted(int(m.group(1)) for p in d.iterdir() if (m := CHUNK_RE.match(p.name)))
