"""`handskin experiment fault-aware`: networks fine-tuned with sensor faults injected, against
the plain ones, under Test B (taxels removed) and Test A (blind spots).

    run_fault_aware("data/forearm", "out/fault-aware", classifier="clf.pt", segmenter="seg.pt")

The fault-aware network starts from the plain one's weights and is trained ``epochs`` more
epochs on the train part plus K faulty copies of it (``robustness_faults``: blind spots, dead
modules, gain drift, and maps with 10-70 % of the taxels removed, drawn from streams the
evaluation never uses) at a tenth of the preset's learning rate. Both are then evaluated on the
same regenerated images; curves are charted side by side with the paper's 92.67 % at 60 %.
"""

from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated

import typer

from learn.experiments.models import DEVICE_HELP
from learn.experiments.robustness_faults import FaultMix
from learn.experiments.robustness_models import QUICK_PLAN
from learn.experiments.robustness_setup import Scale
from tactile.errors import ConfigError, HandskinError


@dataclass(frozen=True)
class FaultAwareScale:
    """Sizes of a fault-aware run.

    eval : the Test A grid and Test B shares, patterns and test subsets of the evaluation.
    epochs : (classifier, segmenter) fine-tuning epochs. n_train : (classifier, segmenter)
    train samples used, seeded subsets (None: all). copies : faulty copies per train sample.
    lr_factor : fine-tuning learning rate / the preset's. mix : the faults drawn.
    """

    eval: Scale
    epochs: tuple[int, int]
    n_train: tuple[int | None, int | None]
    copies: int
    lr_factor: float = 0.1
    mix: FaultMix = field(default_factory=FaultMix)

    def __post_init__(self) -> None:
        if min(self.epochs) < 1 or self.copies < 1 or not self.lr_factor > 0:
            raise ConfigError(
                f"fault-aware training: epochs and copies >= 1, lr factor > 0; "
                f"got {self.epochs}, {self.copies}, {self.lr_factor}"
            )


FULL_FA = FaultAwareScale(
    Scale(5, None, 128, n_spots=(2, 4), radii_mm=(20.0, 40.0)),
    epochs=(3, 2),
    n_train=(None, 600),
    copies=2,
)
QUICK_FA = FaultAwareScale(
    Scale(1, 300, 40, n_spots=(4,), radii_mm=(40.0,), plan=QUICK_PLAN),
    epochs=(1, 1),
    n_train=(400, 200),
    copies=1,
)


def fault_aware_model(
    plain: Path,
    data,
    out: Path,
    *,
    epochs: int,
    n_train: int | None,
    scale: FaultAwareScale,
    seed: int,
    progress: bool,
) -> dict:
    """Fine-tune ``plain`` with faulty copies into ``out`` (reused when finished there, resumed
    when stopped); returns {checkpoint, minutes, train images} (None when reused), minutes
    being the epochs' own training time summed over every part of a resumed run."""
    from learn.checkpoint import load_checkpoint
    from learn.experiments.models import train_once
    from learn.experiments.robustness_faults import augmented_data
    from learn.train import replace_train, run_from_dict

    recipe = {
        "from": str(plain),
        "epochs": epochs,
        "n_train": n_train,
        "seed": seed,
        "copies": scale.copies,
        "lr_factor": scale.lr_factor,
        "mix": dataclasses.asdict(scale.mix),
    }
    if (out / "last.pt").is_file() or (out / "best.pt").is_file():
        _check_recipe(out, recipe)
    else:  # written before training, so a stopped run still matches it when resumed
        out.mkdir(parents=True, exist_ok=True)
        (out / RECIPE).write_text(json.dumps(recipe, indent=1))
    run = run_from_dict(load_checkpoint(plain)["config"])
    run = replace_train(run, epochs=epochs, lr=run.train.lr * scale.lr_factor, seed=seed)
    # no type head and no teacher: both are training aids of the plain run (`learn.aux_types`,
    # `learn.distill`), and the faulty copies carry no contactor types; the fine-tuned network
    # is the same plain network
    run = dataclasses.replace(
        run, flips=False, device=scale.eval.plan.device, aux_types_weight=0.0, distill_from=""
    )
    made: list = []  # the augmented data, when this call trains

    def make_data():
        made.append(augmented_data(data, run, n_train, scale.copies, scale.mix, seed, progress))
        return made[0]

    resumed = (out / "last.pt").is_file()
    best, trained = train_once(out, run, make_data, init_from=plain, progress=progress)
    if not trained:
        return {"checkpoint": str(best), "minutes": None, "train_images": None}
    # the epochs' own seconds, summed over every part of a resumed run (not this call's clock)
    seconds = sum(row["seconds"] for row in load_checkpoint(out / "last.pt")["history"])
    return {
        "checkpoint": str(best),
        "train_images": len(made[0].train.y),
        "minutes": seconds / 60,
        "resumed": resumed,
        "epochs": epochs,
        "lr": run.train.lr,
    }


RECIPE = "fault_aware.json"  # how a fault-aware network was made, beside its best.pt


def _check_recipe(out: Path, recipe: dict) -> None:
    """ConfigError unless the network in ``out`` was made by ``recipe``."""
    path = out / RECIPE
    found = json.loads(path.read_text()) if path.is_file() else None
    if found != json.loads(json.dumps(recipe)):
        raise ConfigError(
            f"{out} holds a fault-aware network made otherwise ({path}: {found}); "
            "remove the folder or give another --models folder"
        )


def run_fault_aware(
    data,
    out,
    *,
    scale: FaultAwareScale = FULL_FA,
    seed: int = 0,
    classifier=None,
    segmenter=None,
    models_dir=None,
    threads: int = 2,
    progress: bool = True,
) -> Path:
    """Train the fault-aware networks, evaluate both kinds; returns the report's path."""
    from learn.experiments.report import Report
    from learn.experiments.robustness_eval import Predictor, blind_spot_study, removal_study
    from learn.experiments.robustness_fa_report import write_report
    from learn.experiments.robustness_setup import check_inputs, config_of, prepare

    check_inputs(data, classifier, segmenter, threads, scale.eval.plan.device)
    rep = Report(
        "fault-aware",
        out,
        seed=seed,
        config={
            **config_of(data, scale.eval, classifier, segmenter, threads),
            "fault_aware": dataclasses.asdict(scale),
        },
    )
    prep = prepare(
        data, out, scale.eval, seed, classifier, segmenter, models_dir, threads, progress
    )
    plain, info, frames = prep.models, prep.info, prep.frames
    tic = time.perf_counter()
    models_dir = Path(models_dir) if models_dir is not None else Path(out) / "models"
    suffix = scale.eval.plan.suffix
    aware, trained = [], []
    for k, (net, desc) in enumerate(zip(plain, info, strict=True)):
        arch = desc["model"]["arch"]
        res = fault_aware_model(
            Path(desc["checkpoint"]),
            data,
            models_dir / f"{arch}_fault_aware{suffix}",
            epochs=scale.epochs[k],
            n_train=scale.n_train[k],
            scale=scale,
            seed=seed,
            progress=progress,
        )
        aware.append(Predictor.load(f"{net.name} fault-aware", res["checkpoint"]))
        trained.append({"name": aware[-1].name, "from": desc["checkpoint"], **res})
    models = [plain[0], aware[0], plain[1], aware[1]]
    ev = scale.eval
    prep.minutes["fault_aware_training"] = (time.perf_counter() - tic) / 60
    tic = time.perf_counter()
    study_b = removal_study(frames, models, ev.fractions, ev.n_patterns, seed, progress)
    prep.minutes["test_b"] = (time.perf_counter() - tic) / 60
    tic = time.perf_counter()
    spots = [(n, r) for n in ev.n_spots for r in ev.radii_mm]
    study_a = blind_spot_study(frames, models, spots, ev.n_patterns, seed, progress)
    prep.minutes["test_a"] = (time.perf_counter() - tic) / 60
    return write_report(rep, data, scale, models, prep, trained, study_a, study_b)


def _opt(kind, help_text: str):
    return Annotated[kind, typer.Option(help=help_text)]


OutOpt = _opt(Path, "Output folder: report.md, results.json, PNG charts, models/.")
DataOpt = _opt(Path, "Dataset folder (holding dataset.h5).")
QuickOpt = _opt(
    bool,
    "Small run (minutes): 1 epoch on 400 / 200 train samples with 1 faulty "
    "copy each; 1 pattern per condition, 300 test samples classified, 40 segmented.",
)
SeedOpt = _opt(int, "Seed of every random draw: faults, patterns, subsets (integer).")
ClfOpt = _opt(
    Path | None,
    "Plain classifier checkpoint (.pt file); default: trained here as robustness-a does.",
)
SegOpt = _opt(Path | None, "Plain segmenter checkpoint (.pt file); default: trained here.")
EpochsOpt = _opt(
    int | None,
    "Fine-tuning epochs of both networks (count; default 3 for the "
    "classifier and 2 for the segmenter, --quick 1).",
)
CopiesOpt = _opt(int | None, "Faulty copies of each train sample (count; default 2, --quick 1).")
PatternsOpt = _opt(int | None, "Random patterns per condition (count; default 5, --quick 1).")
LrOpt = _opt(float | None, "Fine-tuning learning rate / the plain run's (ratio; default 0.1).")
ModelsOpt = _opt(Path | None, "Folder of networks trained here and reused (default OUT/models).")
ThreadsOpt = _opt(int, "CPU threads used by torch (count).")
DeviceOpt = _opt(str, DEVICE_HELP)
ProgressOpt = _opt(bool, "Show progress bars.")


def fault_aware_command(
    out: OutOpt,
    data: DataOpt,
    quick: QuickOpt = False,
    seed: SeedOpt = 0,
    classifier: ClfOpt = None,
    segmenter: SegOpt = None,
    epochs: EpochsOpt = None,
    copies: CopiesOpt = None,
    patterns: PatternsOpt = None,
    lr_factor: LrOpt = None,
    models: ModelsOpt = None,
    threads: ThreadsOpt = 2,
    device: DeviceOpt = "cpu",
    progress: ProgressOpt = True,
) -> None:
    """Fault-aware training (see ``FA_HELP``)."""
    from learn.cli import _fail

    try:
        scale = QUICK_FA if quick else FULL_FA
        changes = {
            "epochs": None if epochs is None else (epochs, epochs),
            "copies": copies,
            "lr_factor": lr_factor,
        }
        scale = dataclasses.replace(scale, **{k: v for k, v in changes.items() if v is not None})
        scale = dataclasses.replace(scale, eval=scale.eval.changed(patterns, None, None, device))
        path = run_fault_aware(
            data,
            out,
            scale=scale,
            seed=seed,
            classifier=classifier,
            segmenter=segmenter,
            models_dir=models,
            threads=threads,
            progress=progress,
        )
    except (HandskinError, KeyError) as err:
        raise _fail(err) from err
    typer.echo(f"report written to {path}")


def register(app: typer.Typer) -> None:
    """Add `fault-aware` to `handskin experiment`."""
    from learn.cli import _needs_torch

    app.command("fault-aware", help=FA_HELP)(_needs_torch(fault_aware_command))


FA_HELP = (
    "Fault-aware training: HandsNet and SegNet fine-tuned with blind spots, removed "
    "taxels, dead modules and gain drift injected; Test B and Test A curves beside the "
    "plain networks, the paper's 92.67 % at 60 % removed marked."
)
