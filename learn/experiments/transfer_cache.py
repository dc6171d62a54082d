"""Fine-tuning results of a transfer run kept on disk, so a stopped run resumes where it stopped.

At the paper's 120 epochs one fine-tuning run (one starting point, one train-set size) takes up
to half an hour on two cores, and the full setting makes fifteen. Each result is written
atomically to ``<models>/finetune/<task>-<start>-<n>.json`` together with the key it was computed
for; a rerun whose key is equal reads it instead of training:

    res = cached(path, finetune_key(run, init, target, samples), lambda: train_and_score())

The key holds everything the result depends on: the run configuration, the starting checkpoint's
bytes (sha256), the target dataset (its fingerprint and size) and the train samples.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Callable
from pathlib import Path


def finetune_key(run, init: Path | None, target: Path, samples: list[int]) -> dict:
    """The JSON-able key of one fine-tuning result (see module doc)."""
    from tactile.config import to_dict
    from tactile.dataset.reader import DatasetReader

    with DatasetReader(target) as ds:
        dataset = {"fingerprint": ds.attrs.get("fingerprint"), "n": len(ds)}
    if init is None:
        start = None
    else:
        with open(init, "rb") as f:
            start = hashlib.file_digest(f, "sha256").hexdigest()
    key = {
        "config": to_dict(run),
        "init": start,
        "target": dataset,
        "samples": hashlib.sha256(json.dumps(samples).encode()).hexdigest(),
    }
    return json.loads(json.dumps(key))  # as it reads back from the file (tuples as lists)


def cached(path: Path, key: dict, compute: Callable[[], dict]) -> dict:
    """The result stored at ``path`` for ``key``, or ``compute()`` written there first."""
    if path.is_file():
        try:
            stored = json.loads(path.read_text(encoding="utf-8"))
        except ValueError:
            stored = {}
        if stored.get("key") == key:
            print(f"reusing {path}")
            return stored["result"]
    result = compute()
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps({"key": key, "result": result}), encoding="utf-8")
    os.replace(tmp, path)
    return result
