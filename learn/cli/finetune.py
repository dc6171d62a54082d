"""`handskin finetune`: a segmenter trained on simulation, fine-tuned on real box-labelled prints
with the recipe chosen on held-out real prints (`learn.train.finetune`)."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Annotated

import typer

from learn.cli.options import ProgressOpt, ThreadsOpt, fail, opt
from learn.train.finetune import FinetuneRecipe
from tactile.dataset.boxes import BoxFolder, is_box_folder
from tactile.errors import ConfigError, DataError, HandskinError, require_folder
from tactile.files import os_error_text, require_output, write_text_atomic

RealArg = Annotated[
    Path,
    typer.Argument(
        metavar="REAL", help="Box folder of real prints, parts boxed (handskin ingest-boxes)."
    ),
]
RUN_FILES = ("best.pt", "last.pt")  # a run folder's weights: never written over


def finetune_command(
    real: RealArg,
    init: opt(Path, "Segmenter trained on simulation (.pt) to start from.", "--init"),
    out: opt(Path, "New run folder: best.pt, last.pt, run.toml, curves.png, finetune.json."),
    replay_from: opt(
        Path | None,
        "Simulated dataset whose train split is replayed (default: the one --init trained on).",
    ) = None,
    replay: opt(
        int, "Simulated prints replayed beside the real ones (count; 0: none)."
    ) = FinetuneRecipe.replay,
    steps: opt(int, "Optimisation steps, whatever the number of prints (count).") = (
        FinetuneRecipe.steps
    ),
    shift_mm: opt(
        float, "Copies of the real prints moved up to this far on the map (mm; 0: not moved)."
    ) = FinetuneRecipe.shift_mm,
    turn_deg: opt(
        float, "Copies of the real prints turned up to this much (deg; 0: not turned)."
    ) = FinetuneRecipe.turn_deg,
    seed: opt(int, "Seed of the replay pick, the copies and training (integer >= 0).") = 0,
    threads: ThreadsOpt = 2,
    progress: ProgressOpt = True,
) -> None:
    """Fine-tune a segmenter trained on simulation on real box-labelled prints (REAL).

    The recipe chosen on held-out real prints: simulated prints replayed beside the real
    ones, each real print repeated to about as many, its copies moved and turned; a fixed
    number of steps. Score it with `handskin evaluate OTHER_REAL OUT/best.pt`.
    """
    try:
        if seed < 0:
            raise ConfigError(f"--seed {seed}: an integer >= 0")
        if threads < 1:
            raise ConfigError(f"--threads {threads}: a count >= 1")
        recipe = FinetuneRecipe(steps, replay, shift_mm, turn_deg, seed, threads)
        if not is_box_folder(real):
            raise DataError(
                f"REAL {real}: not a box folder (images/, labels/, data.yaml). Fix: handskin "
                "ingest-boxes first; a handskin dataset fine-tunes with handskin train --init"
            )
        if not init.is_file():
            raise DataError(f"--init {init}: no such file. Fix: a segmenter's best.pt")
        require_folder(out)
        require_output(out, "--out", reads=[real, init, replay_from], folder=True, makes="run")
        held = [name for name in RUN_FILES if (out / name).exists()]
        if held:
            raise ConfigError(
                f"--out {out} already holds a run ({', '.join(held)}), which fine-tuning would "
                "write over. Fix: another --out"
            )
        _finetune(real, init, out, replay_from, recipe, progress)
    except (HandskinError, KeyError) as err:
        raise fail(err) from err
    except OSError as err:  # a full disk while writing the run folder
        raise fail(ValueError(os_error_text(err))) from err


def _finetune(real, init, out, sim, recipe: FinetuneRecipe, progress: bool) -> None:
    # optional: torch (the learn extra)
    import torch

    from learn.data.boxes import BoxFolderDataset
    from learn.data.load import materialize
    from learn.train.checkpoint import load_checkpoint, run_of, versions
    from learn.train.finetune import copies_of, finetune, replay_prints, replay_source, shift_px

    ckpt = load_checkpoint(init)
    base = run_of(ckpt, init)
    if base.task != "segment":
        raise ConfigError(
            f"--init {init}: a '{base.task}' network. Fix: a segmenter (handskin train --arch "
            "segnet)"
        )
    sim, sim_print, sim_ds = replay_source(sim, base, recipe, ckpt, f"--init {init}")
    folder = BoxFolder.open(real)  # every check passed: now the work
    torch.set_num_threads(recipe.threads)
    size = base.model.input_size
    source = BoxFolderDataset(real, None, "segment", size, flips=False)
    prints = materialize(source, "real", progress)
    shift = shift_px(recipe, folder.frame_px or folder[0].image.shape, size)
    copies = copies_of(len(prints.y), recipe)
    desc = {"path": str(real), "kind": "box folder", "real_prints": len(prints.y)}
    desc |= {"copies": copies, "init": str(init), "recipe": dataclasses.asdict(recipe)}
    desc |= {"replay_from": None if sim is None else str(sim), "replay_fingerprint": sim_print}
    typer.echo(
        f"fine-tuning {init} on {len(prints.y)} real prints x {copies} copies"
        + (f" and {recipe.replay} simulated from {sim}" if sim is not None else "")
        + f", {recipe.steps} steps"
    )
    replay = replay_prints(sim_ds, recipe)
    finetune(
        base, prints, replay, shift, recipe, init=ckpt, out=out, description=desc, progress=progress
    )
    write_text_atomic(out / "finetune.json", json.dumps(desc | {"versions": versions()}, indent=1))
    typer.echo(f"run written to {out}; score it: handskin evaluate OTHER_REAL {out / 'best.pt'}")
