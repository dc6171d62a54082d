"""`handskin experiment fault-aware`: networks fine-tuned with sensor faults injected, against
the plain ones, under Test B (taxels removed) and Test A (blind spots).

    run_fault_aware("data/forearm", "out/fault-aware", classifier="clf.pt", segmenter="seg.pt")

Each fault-aware network starts from the plain one's weights and trains ``epochs`` more epochs,
without flips, on the train part plus K faulty copies of it (``experiments.faults``: blind
spots, dead modules, gain drift and maps with 10-70 % of the taxels removed, drawn from streams
the evaluation never uses) at ``lr_factor`` times the plain run's learning rate; the
subject-disjoint validation part, clean plus as many faulty copies, picks the best epoch. The
plain network gets no extra epochs. Both are evaluated on the same regenerated images.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from pathlib import Path

from experiments import experiment
from experiments import options as O
from experiments.settings import QUICK_PLAN, FaultMix, Scale, changed
from tactile.errors import ConfigError

RECIPE = "fault_aware.json"  # how a fault-aware network was made, beside its best.pt


@dataclass(frozen=True)
class FaultAwareScale:
    """Sizes of a fault-aware run.

    eval : the Test A grid and Test B shares, patterns and test subsets of the evaluation.
    epochs : (classifier, segmenter) fine-tuning epochs. n_train : (classifier, segmenter)
    train samples, seeded subsets (None: all). copies : faulty copies per train sample.
    lr_factor : fine-tuning learning rate / the plain run's. mix : the faults drawn.
    """

    eval: Scale
    epochs: tuple[int, int]
    n_train: tuple[int | None, int | None]
    copies: int
    lr_factor: float = 0.1
    mix: FaultMix = field(default_factory=FaultMix)

    def __post_init__(self) -> None:
        O.check_at_least("--epochs", min(self.epochs))
        O.check_at_least("--copies", self.copies)
        if not self.lr_factor > 0:
            raise ConfigError(f"lr factor {self.lr_factor}: give a factor > 0")


FULL_FA = FaultAwareScale(
    Scale(5, None, 128, n_spots=(2, 4), radii_mm=(20.0, 40.0)), (3, 2), (None, 600), copies=2
)
QUICK_FA = FaultAwareScale(
    Scale(1, 300, 40, n_spots=(4,), radii_mm=(40.0,), plan=QUICK_PLAN), (1, 1), (400, 200), 1
)


def fault_aware_model(plain: Path, data, out: Path, *, epochs, n_train, scale, seed, progress):
    """Fine-tune ``plain`` with faulty copies into ``out`` (reused when finished there, resumed
    when stopped); returns {checkpoint, minutes, train_images} (None when reused), minutes being
    the epochs' own training time summed over every part of a resumed run."""
    # optional: torch (the learn extra)
    from experiments.faults import augmented_data
    from learn.config import replace_train
    from learn.train.checkpoint import load_checkpoint, run_of
    from learn.train.runs import train_once

    recipe = {"from": str(plain), "epochs": epochs, "n_train": n_train, "seed": seed}
    recipe |= {"copies": scale.copies, "lr_factor": scale.lr_factor}
    recipe = json.loads(json.dumps(recipe | {"mix": dataclasses.asdict(scale.mix)}))
    resumed = (out / "last.pt").is_file()
    if resumed or (out / "best.pt").is_file():
        found = json.loads((out / RECIPE).read_text()) if (out / RECIPE).is_file() else None
        if found != recipe:
            raise ConfigError(
                f"{out} holds a fault-aware network made otherwise ({out / RECIPE}: {found}). "
                "Fix: delete that folder or give another --models folder"
            )
    else:  # written before training, so that a stopped run still matches it when resumed
        out.mkdir(parents=True, exist_ok=True)
        (out / RECIPE).write_text(json.dumps(recipe, indent=1))
    run = run_of(load_checkpoint(plain), plain)
    run = replace_train(run, epochs=epochs, lr=run.train.lr * scale.lr_factor, seed=seed)
    run = dataclasses.replace(run, flips=False, device=scale.eval.plan.device)
    made = []

    def make_data():
        made.append(augmented_data(data, run, n_train, scale.copies, scale.mix, seed, progress))
        return made[0]

    best, trained = train_once(out, run, make_data, init=plain, progress=progress)
    if not trained:
        return {"checkpoint": str(best), "minutes": None, "train_images": None}
    seconds = sum(row["seconds"] for row in load_checkpoint(out / "last.pt")["history"])
    res = {"checkpoint": str(best), "train_images": len(made[0].train.y), "minutes": seconds / 60}
    return res | {"resumed": resumed, "epochs": epochs, "lr": run.train.lr}


def run_fault_aware(data, out, scale: FaultAwareScale = FULL_FA, seed: int = 0, **nets) -> Path:
    """Train the fault-aware networks, evaluate both kinds; returns the report's path
    (``nets``: as ``experiments.robustness.run_robustness_a``'s)."""
    # optional: torch (the learn extra)
    from experiments import tables as T
    from experiments.networks import Predictor, start
    from experiments.studies import blind_spot_study, removal_study

    ev = scale.eval
    rep, prep = start(
        "fault-aware", data, out, ev, seed, fault_aware=dataclasses.asdict(scale), **nets
    )
    folder, progress = prep.models_dir, prep.progress
    models, trained = [], []
    for net, desc in zip(prep.models, prep.info, strict=True):
        k, arch = int(net.task == "segment"), desc["model"]["arch"]
        res = fault_aware_model(
            Path(desc["checkpoint"]),
            data,
            folder / f"{arch}_fault_aware{ev.plan.suffix}",
            epochs=scale.epochs[k],
            n_train=scale.n_train[k],
            scale=scale,
            seed=seed,
            progress=progress,
        )
        models += [net, Predictor.load(f"{net.name} fault-aware", res["checkpoint"])]
        trained.append({"name": models[-1].name, "from": desc["checkpoint"], **res})
    study_b = removal_study(prep.frames, models, ev.fractions, ev.n_patterns, seed, progress)
    spots = [(n, r) for n in ev.n_spots for r in ev.radii_mm]
    study_a = blind_spot_study(prep.frames, models, spots, ev.n_patterns, seed, progress)
    rep.section("Setup", T.setup_text(data, prep, training_text(scale, trained)))
    rep.section(
        "Zero corruption (regenerated images)", T.baseline_table(study_a["baseline"], models)
    )
    curves = {m.name: T.removal_summaries(study_b, m.name, m.task) for m in models}
    T.write_removal(rep, models, curves, "fa_")
    T.write_spots(rep, models, study_a, charts=False)
    results = {"test_a": study_a, "test_b": study_b, "networks": prep.info, "trained": trained}
    return rep.write(results | {"curves": curves})


def training_text(scale: FaultAwareScale, trained: list[dict]) -> str:
    """The fault-aware networks' training, in words."""
    mix = ", ".join(f"{k} {v}" for k, v in dataclasses.asdict(scale.mix).items())
    (e_c, e_s), (n_c, n_s) = scale.epochs, (n or "all" for n in scale.n_train)
    text = (
        f"Each fault-aware network starts from the plain one and trains {e_c} (classifier) or "
        f"{e_s} (segmenter) more epochs, without flips, on {n_c} or {n_s} train samples plus "
        f"{scale.copies} faulty copies of each, at {scale.lr_factor:g} x the plain run's "
        "learning rate; the validation part, clean plus as many faulty copies, picks the best "
        f"epoch. The plain networks get no extra epochs. Faults per copy: {mix}.\n"
    )
    for t in trained:
        how = "reused" if t["minutes"] is None else f"trained {t['minutes']:.1f} min"
        text += f"\n- {t['name']}: `{t['checkpoint']}` from `{t['from']}` ({how})"
    return text


@experiment("fault-aware")
def fault_aware(
    dataset: O.DatasetArg,
    out: O.OutOpt,
    quick: O.QuickOpt = False,
    seed: O.SeedOpt = 0,
    classifier: O.ClassifierOpt = None,
    segmenter: O.SegmenterOpt = None,
    segmentation: O.SegmentationOpt = True,
    epochs: O.opt(int | None, "Fine-tuning epochs (count; default 3, the segmenter 2).") = None,
    copies: O.opt(int | None, "Faulty copies of each train sample (count; default 2).") = None,
    patterns: O.opt(int | None, "Random patterns per condition (count; default 5).") = None,
    models: O.ModelsOpt = None,
    threads: O.ThreadsOpt = 2,
    device: O.DeviceOpt = "cpu",
    progress: O.ProgressOpt = True,
) -> Path:
    """Fault-aware training: networks fine-tuned with sensor faults, under Tests B and A.

    The classifier and the segmenter are fine-tuned with blind spots, removed taxels, dead
    modules and gain drift injected, then scored beside the plain networks; the paper's
    accuracy at 60 % of the taxels removed is marked.

    --quick: 1 epoch on 400 / 200 train samples with 1 faulty copy each; 1 pattern per
    condition, 300 test samples classified, 40 segmented.
    """
    O.check_segmenter(segmentation, segmenter)
    scale = QUICK_FA if quick else FULL_FA
    changes = {"epochs": None if epochs is None else (epochs, epochs), "copies": copies}
    changes = {k: v for k, v in changes.items() if v is not None}
    ev = changed(scale.eval, patterns, segmentation, device)
    scale = dataclasses.replace(scale, eval=ev, **changes)
    nets = {"classifier": classifier, "segmenter": segmenter, "models_dir": models}
    return run_fault_aware(dataset, out, scale, seed, threads=threads, progress=progress, **nets)
