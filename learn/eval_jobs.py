"""What `handskin evaluate` scores: one row per checkpoint or model file, one more per network
with test-time flips (``--tta``), per task's ensemble (``--ensemble``) and per HandsNet as int8
(``--int8``); every file is loaded and checked before any scoring starts.

    jobs = eval_jobs([Path("runs/hn/best.pt"), Path("runs/bovw/model.npz")], tta=True)
    # [(path or list of paths, with test-time flips, as int8), ...]
"""

from __future__ import annotations

from pathlib import Path

from tactile.errors import ConfigError

Job = tuple[Path | list[Path], bool, bool]


def eval_jobs(
    checkpoints: list[Path], tta: bool = False, ensemble: bool = False, int8: bool = False
) -> list[Job]:
    """The report's rows, in order, as (checkpoint, or an ensemble's list of them; with
    test-time flips; as int8). ConfigError / DataError naming the fix on a file that does not
    load, a network trained without flips under ``tta``, or nothing to ensemble or quantize."""
    from learn.checkpoint import load_checkpoint
    from learn.classical import load_npz
    from learn.evaluate import tta_views
    from learn.run_config import run_from_dict

    jobs: list[Job] = []
    by_task: dict[str, list[Path]] = {}
    loaded = {}  # each .pt file, read once
    for c in checkpoints:
        if c.suffix == ".npz":
            load_npz(c)
            jobs.append((c, False, False))
            continue
        loaded[c] = load_checkpoint(c)
        run = run_from_dict(loaded[c]["config"])
        if tta:  # a network trained without flips fails here, before any work
            tta_views(run, c)
        by_task.setdefault(run.task, []).append(c)
        jobs += [(c, False, False)] + ([(c, True, False)] if tta else [])
    jobs += ensemble_jobs(by_task, tta) if ensemble else []
    jobs += int8_jobs(loaded) if int8 else []
    return jobs


def int8_jobs(ckpts: dict[Path, dict]) -> list[tuple[Path, bool, bool]]:
    """``--int8``'s jobs: every float HandsNet among the loaded ``.pt`` checkpoints (path ->
    checkpoint dict); a ConfigError if none is."""
    from learn.int8_file import is_int8

    nets = [
        c for c, k in ckpts.items() if k["config"]["model"]["arch"] == "handsnet" and not is_int8(k)
    ]
    if not nets:
        saved = any(is_int8(k) for k in ckpts.values())
        raise ConfigError(
            "--int8 scores HandsNet as an int8 network; no float HandsNet "
            "checkpoint was given"
            + (" (int8 files of handskin quantize are scored as int8 without it)" if saved else "")
            + ". Fix: add a "
            "HandsNet .pt file, or drop --int8"
        )
    return [(c, False, True) for c in nets]


def ensemble_jobs(
    by_task: dict[str, list[Path]],
    tta: bool,
) -> list[tuple[list[Path], bool, bool]]:
    """``--ensemble``'s jobs: each task's networks together, checked alike before any work."""
    from learn.ensemble import load_members

    groups = [paths for paths in by_task.values() if len(paths) >= 2]
    if not groups:
        counts = ", ".join(f"{len(p)} {t}" for t, p in by_task.items()) or "no networks"
        raise ConfigError(
            f"--ensemble averages two or more networks of one task; got {counts}. "
            "Fix: give two or more classifier or segmenter .pt files"
        )
    for paths in groups:
        load_members(paths)
    return [(paths, t, False) for paths in groups for t in ((False, True) if tta else (False,))]
