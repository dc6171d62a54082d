"""Checks of what `handskin verify` reads beside the data, before it uses them: the shape of a
JSON sidecar's values, the manifest's fingerprint against its identity fields (an edit shows),
an unmerged run's chunks against the chunks its manifest's configuration writes."""

from __future__ import annotations

import json
from pathlib import Path

from tactile.dataset.folder import chunk_path, list_chunks
from tactile.dataset.manifest import IDENTITY, MANIFEST, expected_chunks, fingerprint_of

MAX_LISTED = 10  # chunks listed per kind of fault


def digest_fault(want: object) -> str | None:
    """What keeps ``want`` from being `file_digest`'s {"sha256": 64 hex digits, "bytes": a
    count}, in words; None when it is one."""
    if not isinstance(want, dict):
        return f"{json_kind(want)}, not an object"
    if set(want) != {"sha256", "bytes"}:
        return f"keys {', '.join(map(str, want)) or 'none'}, not sha256 and bytes"
    sha, size = want["sha256"], want["bytes"]
    if not (isinstance(sha, str) and len(sha) == 64 and set(sha) <= set("0123456789abcdef")):
        return f"sha256 {json_kind(sha)}, not 64 hex digits"
    if not (isinstance(size, int) and not isinstance(size, bool) and size >= 0):
        return f"bytes {json_kind(size)}, not a count"
    return None


def json_kind(value: object) -> str:
    """A JSON value in words: ``null``, ``a list``, ``the number 12345``, ..."""
    if value is None or isinstance(value, bool):
        return json.dumps(value)
    if isinstance(value, dict | list):
        return f"a{'n object' if isinstance(value, dict) else ' list'} {json.dumps(value)[:40]}"
    kind = "text" if isinstance(value, str) else "the number"
    return f"{kind} {json.dumps(value)[:40]}"


def fingerprint_faults(folder: Path, manifest: dict) -> list[str]:
    """A fault when the manifest's fingerprint is not that of its identity fields (edited)."""
    want = fingerprint_of(manifest)
    if manifest.get("fingerprint") == want:
        return []
    return [
        f"{folder / MANIFEST}: fingerprint {str(manifest.get('fingerprint'))[:12]} is not that of "
        f"its {', '.join(IDENTITY)} ({want[:12]}): the file was edited since its run wrote it, "
        "so it may not say what the data were made from. Fix: restore the manifest the run "
        "wrote, or regenerate into a new folder"
    ]


def run_chunk_faults(folder: Path, manifest: dict) -> tuple[list[str], list[str]]:
    """(faults, notes) of an unmerged run's chunks against the ceil(n / chunk_size) its
    ``manifest`` writes: a missing or extra chunk is a fault, a shard's chunks a note."""
    k, have = expected_chunks(manifest), list_chunks(folder)
    if k is None:
        return [], []
    missing, extra = sorted(set(range(k)) - set(have)), sorted(set(have) - set(range(k)))
    step = have[1] - have[0] if len(have) > 1 else 0
    if not extra and step > 1 and have[0] < step and have == list(range(have[0], k, step)):
        note = (
            f"chunks {have[0]}, {have[1]}, ... of {k}: shard {have[0]}/{step} of a run "
            "(generate --shard). Fix: join the shards with handskin merge SHARD... --out DIR"
        )
        return [], [note]
    faults = [
        f"{chunk_path(folder, m)}: missing; the run of {MANIFEST} writes chunks 0..{k - 1}. "
        f"Fix: rerun the same handskin generate --out {folder}: it computes the missing "
        "chunks, then merges"
        for m in missing[:MAX_LISTED]
    ]
    faults += [
        f"{chunk_path(folder, e)}: a chunk beyond the run's {k} ({MANIFEST}): not of this "
        "run. Fix: move it out of the folder"
        for e in extra[:MAX_LISTED]
    ]
    return faults, []
