"""`handskin experiment transfer`: Test C of Albini & Cannata (IJRR 2020) — the forearm model on
end-effector data, zero-shot (Table 15) and fine-tuned (Table 16); the generator's own answer,
pretraining on synthetic end-effector data; and the learning curve of fine-tuning against the
number of end-effector samples, from scratch, from the forearm and from the synthetic model.

This module is the thin part that uses ``sim``: it generates, or reuses when the folder already
holds a ``dataset.h5``, three datasets whose seeds derive from ``--seed``:
- source: the forearm (``--source``; default OUT/data/forearm, 3,530 samples, quick 600),
- target: the end-effector (``--target``; default OUT/data/end_effector, 1,000, quick 200),
- pretraining: a second synthetic end-effector set (``--pretrain-data``; default
  OUT/data/end_effector_synthetic, 1,000, quick 400), of another seed.
The learning is ``learn.experiments.transfer_lib``; this module writes the report around it.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from learn.experiments.models import DEVICE_HELP
from learn.experiments.transfer_lib import TransferSettings
from tactile.errors import ConfigError, HandskinError

ROLES = ("source", "target", "pretrain")  # spawn keys of the dataset seeds, in this order
PARTS = {"source": "forearm", "target": "end_effector", "pretrain": "end_effector"}
FOLDERS = {"source": "forearm", "target": "end_effector", "pretrain": "end_effector_synthetic"}


@dataclass(frozen=True)
class DataPlan:
    """Sizes (samples) of the datasets generated here, and how they are generated."""

    n_source: int = 3530  # forearm samples (the paper's dataset size)
    n_target: int = 1000  # end-effector samples (70 % train / 30 % test, subject-disjoint)
    n_pretrain: int = 1000  # synthetic end-effector pretraining samples
    workers: int = 1  # generation processes (count); the bytes do not depend on it
    tiny: bool = False  # sim.tiny's settings: 6 subjects, 2 instances per kind, short presses

    def __post_init__(self) -> None:
        if self.workers < 1:
            raise ConfigError(f"workers = {self.workers} is out of range; allowed >= 1 processes")

    def n(self, role: str) -> int:
        return {"source": self.n_source, "target": self.n_target, "pretrain": self.n_pretrain}[role]


QUICK_DATA = DataPlan(n_source=600, n_target=200, n_pretrain=400)
#: The quick learning settings: 3 fine-tuning epochs, 1 pretraining epoch without flips.
QUICK_SETTINGS = TransferSettings(
    curve_sizes=(10, 30), finetune_epochs=3, pretrain_epochs=1, pretrain_flips=False
)


def dataset_seed(seed: int, role: str) -> int:
    """Seed of the generated dataset of ``role``: a pure function of the experiment seed."""
    seq = np.random.SeedSequence(seed, spawn_key=(ROLES.index(role),))
    return int(seq.generate_state(1, np.uint32)[0])


def generate_config(role: str, seed: int, plan: DataPlan):
    """The GenerateConfig of ``role`` (validated: ConfigError names the field)."""
    from sim.episode import EpisodeConfig
    from sim.gen_config import GenerateConfig
    from sim.tiny import TINY_DURATION_SCALE, TINY_MAX_ATTEMPTS

    cfg = {"part": PARTS[role], "n": plan.n(role), "seed": dataset_seed(seed, role)}
    if plan.tiny:
        cfg |= {
            "n_subjects": 6,
            "instances_per_kind": 2,
            "duration_scale": TINY_DURATION_SCALE,
            "episode": EpisodeConfig(max_attempts=TINY_MAX_ATTEMPTS),
        }
    return GenerateConfig(**cfg)


def ensure_dataset(folder: Path, cfg, plan: DataPlan, *, default: bool, progress: bool) -> Path:
    """``folder`` holding the dataset: reused if it has a dataset.h5 (a default folder must hold
    this configuration's part, size and seed), else generated there with ``sim.generate``."""
    from tactile.dataset.reader import DatasetReader

    if (folder / "dataset.h5").is_file():
        with DatasetReader(folder) as ds:
            n, part, seed = len(ds), ds.attrs.get("part"), ds.attrs.get("seed")
        if default and (n, part, seed) != (cfg.n, cfg.part, cfg.seed):
            raise ConfigError(
                f"{folder} holds {n} {part} samples of seed {seed}; this run needs "
                f"{cfg.n} of seed {cfg.seed}. Fix: another --out, or delete "
                f"{folder}"
            )
        print(f"reusing {folder} ({n} samples, part {part})")
        return folder
    from sim.generate import generate

    generate(cfg, folder, workers=plan.workers, progress=progress)
    return folder


def describe(folders: dict[str, Path]) -> str:
    """Markdown list of the datasets used and what sets them apart."""
    from tactile.dataset.reader import DatasetReader

    lines = []
    for role, folder in folders.items():
        with DatasetReader(folder) as ds:
            lines.append(
                f"- {role}: `{folder}` — part {ds.attrs.get('part')}, {len(ds)} samples "
                f"({int(ds['is_hand'][:].sum())} hands), seed {ds.attrs.get('seed')}, "
                f"map {ds.image.shape[1]}×{ds.image.shape[2]} px"
            )
    return "\n".join(lines) + (
        "\n\nThe pretraining and (unless given) target sets are both synthetic: they differ by "
        "seed, hence by simulated people (each set draws its own subject pool from its seed; "
        "the ids s0000… recur but name other people) and by presses. Object and body-part "
        "instances are defined by (type, index) alone, so both sets draw from the same "
        "instances: pretraining samples whose instance is in the target's test split are left "
        "out. The forearm source shares that instance pool too (as the paper's objects were "
        "the same on both parts). With real end-effector recordings, give them as --target."
    )


def run_transfer_experiment(
    out: str | Path,
    *,
    s: TransferSettings | None = None,
    plan: DataPlan | None = None,
    source: Path | None = None,
    target: Path | None = None,
    pretrain: Path | None = None,
    classifier: Path | None = None,
    segmenter: Path | None = None,
    models_dir: Path | None = None,
    progress: bool = True,
) -> dict:
    """Generate or reuse the datasets, then run Test C (``transfer_lib.run_transfer``)."""
    from learn.experiments import transfer_lib as T

    out, s, plan = Path(out), s or TransferSettings(), plan or DataPlan()
    given = {"source": source, "target": target, "pretrain": pretrain}
    cfgs = {role: generate_config(role, s.seed, plan) for role in ROLES}  # validated first
    for task, ckpt in (("classify", classifier), ("segment", segmenter)):
        if ckpt is not None:
            T.model_config(task, Path(ckpt), s)
    folders = {
        role: ensure_dataset(
            Path(given[role] or out / "data" / FOLDERS[role]),
            cfgs[role],
            plan,
            default=given[role] is None,
            progress=progress,
        )
        for role in ROLES
    }
    config = {
        "datasets": {k: str(v) for k, v in folders.items()},
        "data_plan": dataclasses.asdict(plan),
        "classifier": classifier,
        "segmenter": segmenter,
    }
    from learn.experiments.transfer_report import run_transfer

    return run_transfer(
        folders["source"],
        folders["target"],
        folders["pretrain"],
        out,
        s,
        classifier=classifier,
        segmenter=segmenter,
        models_dir=models_dir,
        notes=describe(folders),
        config=config,
        progress=progress,
    )


def _opt(kind, help_text: str, *names: str):
    return Annotated[kind, typer.Option(*names, help=help_text)]


def transfer_command(
    out: _opt(
        Path, "Experiment folder (path): report.md, results.json, PNG charts, data/, models/."
    ),
    source: _opt(
        Path | None,
        "Forearm dataset folder (path); reused if it holds dataset.h5, "
        "else generated there. Default OUT/data/forearm.",
        "--source",
        "--data",
    ) = None,
    target: _opt(
        Path | None,
        "End-effector dataset folder (path; real recordings welcome); "
        "reused or generated. Default OUT/data/end_effector.",
    ) = None,
    pretrain_data: _opt(
        Path | None,
        "Synthetic end-effector pretraining dataset folder (path);"
        " reused or generated. Default OUT/data/end_effector_synthetic.",
    ) = None,
    quick: _opt(
        bool,
        "Small version (minutes): 600 / 200 / 400 samples generated, 3 fine-tuning"
        " epochs, 1 pretraining epoch (flips off), N = 10, 30, all.",
    ) = False,
    seed: _opt(int, "Seed (integer) of the generated datasets, initialisation and subsets.") = 0,
    classifier: _opt(
        Path | None,
        "Forearm classifier checkpoint (.pt file); default: trained here on the source.",
    ) = None,
    segmenter: _opt(
        Path | None, "Forearm segmenter checkpoint (.pt file); implies --segmentation."
    ) = None,
    segmentation: _opt(bool, "Also SegNet: zero-shot, fine-tuning and learning curve.") = False,
    classification: _opt(
        bool,
        "HandsNet: zero-shot, fine-tuning and learning curve; "
        "--no-classification with --segmentation runs SegNet alone.",
    ) = True,
    epochs: _opt(
        int | None,
        "Fine-tuning epochs (count; paper 120, quick 3); the lr halves after half of them.",
    ) = None,
    pretrain_epochs: _opt(
        int | None, "Epochs (count) of the models trained here from scratch (default 80, quick 1)."
    ) = None,
    curve: _opt(
        str | None,
        "Learning-curve sizes: comma-separated end-effector train sample "
        "counts ('all' is added). Default 10,30,100,300; quick 10,30.",
    ) = None,
    n_target: _opt(int | None, "End-effector samples to generate (count).") = None,
    n_pretrain: _opt(int | None, "Synthetic pretraining samples to generate (count).") = None,
    n_source: _opt(int | None, "Forearm samples to generate (count).") = None,
    workers: _opt(int, "Generation processes (count).") = 1,
    precision: _opt(
        str,
        "Number format of every training forward pass here: fp32 or bf16 "
        "(as handskin train --precision; about 1.6x faster on CPUs with native "
        "bf16; no unit).",
    ) = "fp32",
    keep_scale: _opt(
        bool,
        "Also run the forearm model at its own scale: each end-effector "
        "image centred on a canvas of the forearm map's size (mm) instead of "
        "stretched to the network input, so a millimetre is as many input pixels "
        "as on the forearm; adds 'forearm at scale' rows.",
    ) = False,
    device: _opt(
        str, DEVICE_HELP + " A fine-tuning result is reused only for the same device."
    ) = "cpu",
    models: _opt(
        Path | None,
        "Folder (path) of the models trained here and of every "
        "fine-tuning result (finetune/*.json); default OUT/models; a rerun reuses them, "
        "so a stopped run resumes.",
    ) = None,
    progress: _opt(bool, "Show progress bars.") = True,
) -> None:
    """Test C: forearm model on the end-effector, fine-tuning, synthetic pretraining, curve."""
    from learn.cli import _fail

    try:
        base = QUICK_SETTINGS if quick else TransferSettings()
        sizes = None if curve is None else _counts(curve)
        changes = {
            "finetune_epochs": epochs,
            "pretrain_epochs": pretrain_epochs,
            "curve_sizes": sizes,
        }
        if classifier is not None and not classification:
            raise ConfigError(
                "--classifier with --no-classification: nothing would use it. Fix: drop one of them"
            )
        s = dataclasses.replace(
            base,
            seed=seed,
            segmentation=segmentation or segmenter is not None,
            classification=classification,
            precision=precision,
            keep_scale=keep_scale,
            device=device,
            **{k: v for k, v in changes.items() if v is not None},
        )
        counts = {"n_target": n_target, "n_pretrain": n_pretrain, "n_source": n_source}
        plan = dataclasses.replace(
            QUICK_DATA if quick else DataPlan(),
            workers=workers,
            **{k: v for k, v in counts.items() if v is not None},
        )
        result = run_transfer_experiment(
            out,
            s=s,
            plan=plan,
            source=source,
            target=target,
            pretrain=pretrain_data,
            classifier=classifier,
            segmenter=segmenter,
            models_dir=models,
            progress=progress,
        )
    except (HandskinError, KeyError) as err:
        raise _fail(err) from err
    typer.echo(f"report written to {result['report']}")


def _counts(text: str) -> tuple[int, ...]:
    try:
        return tuple(int(t) for t in text.split(",") if t.strip() and t.strip() != "all")
    except ValueError:
        raise ConfigError(f"--curve {text!r}: expected sample counts like 10,30,100") from None


def register(app) -> None:
    """Add ``transfer`` to `handskin experiment`."""
    from learn.cli import _needs_torch

    app.command("transfer")(_needs_torch(transfer_command))
