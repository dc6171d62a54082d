"""`handskin experiment transfer`: Test C of Albini & Cannata (IJRR 2020), a model of one skin
part moved to another: the source (forearm) model on the target part zero-shot (the paper's
Table 15) and fine-tuned (Table 16), the generator's own answer (pretraining on synthetic data
of the target part), and the learning curve of fine-tuning against the number of target
samples, from scratch, from the source model and from the synthetic one.

    run_transfer_experiment("data/forearm", "out/transfer", target="end_effector")

SOURCE is a dataset of the source part. ``--target`` is a part name, whose dataset is
generated (or reused) in ``DATASETS/<part>``, or a dataset folder of the target part (real
recordings welcome). A synthetic pretraining set of the target's part is generated in
``DATASETS/<part>_synthetic``. Their seeds derive from ``--seed``. The learning is
``experiments.transfer_runs``; this module makes the datasets and writes the report.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from experiments import experiment
from experiments import options as O
from experiments.report import SEG_LABELS, Report, markdown_table
from tactile.dataset.reader import DatasetReader
from tactile.errors import ConfigError

ROLES = ("source", "target", "pretrain")  # spawn keys of the dataset seeds, in this order
ZERO_SHOT = {  # the starts' names in the results, and in the report
    "forearm": "source model",
    "synthetic EE": "synthetic target-part model (generator)",
    "forearm at scale": "source model at its scale (canvas)",
}
FINETUNED = {"scratch": "from scratch (Test C schedule)"}
FINETUNED |= {k: f"{v}, fine-tuned (Test C)" for k, v in ZERO_SHOT.items()}


@dataclass(frozen=True)
class TransferSettings:
    """What the learning runs; every random draw comes from ``seed``."""

    curve_sizes: tuple[int, ...] = (10, 30, 100, 300)  # target train samples per point (+ all)
    finetune_epochs: int = 120  # Test C recipe (paper: 120, lr halved after half of them)
    pretrain_epochs: int = 80  # models trained here from scratch
    pretrain_flips: bool = True  # the paper's threefold flips while pretraining
    input_size: tuple[int, int] = (68, 100)  # (h, w) px of the models trained here
    segmentation: bool = False  # also SegNet (zero-shot, fine-tuning, curve)
    classification: bool = True  # HandsNet (zero-shot, fine-tuning, curve)
    seed: int = 0
    threads: int = 2  # torch CPU threads
    precision: str = "fp32"  # forward pass of every training here (RunConfig.precision)
    keep_scale: bool = False  # also the source model at its own mm per pixel
    device: str = "cpu"  # where every run here trains (RunConfig.device)

    def __post_init__(self) -> None:
        if not self.curve_sizes or min(self.curve_sizes) < 1:
            raise ConfigError(f"--curve {self.curve_sizes}: give sample counts >= 1")
        for flag, value in (("--epochs", self.finetune_epochs), ("--threads", self.threads)):
            O.check_at_least(flag, value)
        O.check_at_least("--pretrain-epochs", self.pretrain_epochs)
        if not (self.classification or self.segmentation):
            raise ConfigError(
                "neither classification nor segmentation is asked for. Fix: drop "
                "--no-classification or add --segmentation"
            )
        if self.precision not in ("fp32", "bf16"):
            raise ConfigError(f"--precision {self.precision!r}: give fp32 or bf16")

    @property
    def halved_after(self) -> int:
        """Epoch after which Test C halves the lr: half the epochs (paper: 60 of 120), >= 1."""
        return max(1, self.finetune_epochs // 2)


@dataclass(frozen=True)
class DataPlan:
    """Sizes (samples) of the datasets generated here, and how they are generated."""

    n_target: int = 1000  # target samples (70 % train / 30 % test, subject-disjoint)
    n_pretrain: int = 1000  # synthetic pretraining samples of the target part
    workers: int = 1  # generation processes (count); the bytes do not depend on it
    # sim.generate.tiny's settings: 6 subjects, 2 instances per kind, short presses
    tiny: bool = False


QUICK_DATA = DataPlan(n_target=200, n_pretrain=400)
QUICK = TransferSettings(
    curve_sizes=(10, 30), finetune_epochs=3, pretrain_epochs=1, pretrain_flips=False
)


def dataset_seed(seed: int, role: str) -> int:
    """Seed of the generated dataset of ``role``: a pure function of the experiment seed."""
    seq = np.random.SeedSequence(seed, spawn_key=(ROLES.index(role),))
    return int(seq.generate_state(1, np.uint32)[0])


def generate_config(part: str, n: int, seed: int, tiny: bool = False):
    """The GenerateConfig of a generated set (validated: ConfigError names the field)."""
    # start-up time: sim loads MuJoCo
    from sim.episode.runner import EpisodeConfig
    from sim.generate.config import GenerateConfig
    from sim.generate.tiny import TINY_DURATION_SCALE, TINY_MAX_ATTEMPTS

    cfg = {"part": part, "n": n, "seed": seed}
    if tiny:
        cfg |= {"n_subjects": 6, "instances_per_kind": 2, "duration_scale": TINY_DURATION_SCALE}
        cfg |= {"episode": EpisodeConfig(max_attempts=TINY_MAX_ATTEMPTS)}
    return GenerateConfig(**cfg)


def ensure_dataset(folder: Path, cfg, workers: int, progress: bool) -> Path:
    """``folder`` holding the dataset of ``cfg``: reused when its dataset.h5 holds this part,
    size and seed, else generated there (``sim.generate.run``)."""
    from sim.generate.run import generate  # start-up time: sim loads MuJoCo

    if not (folder / "dataset.h5").is_file():
        generate(cfg, folder, workers=workers, progress=progress)
        return folder
    with DatasetReader(folder) as ds:
        n, part, seed = len(ds), ds.attrs.get("part"), ds.attrs.get("seed")
    if (n, part, seed) != (cfg.n, cfg.part, cfg.seed):
        raise ConfigError(
            f"{folder} holds {n} {part} samples of seed {seed}; this run needs {cfg.n} "
            f"{cfg.part} samples of seed {cfg.seed}. Fix: another --datasets, or delete {folder}"
        )
    print(f"reusing {folder} ({n} samples, part {part})")
    return folder


def run_transfer_experiment(
    source,
    out,
    *,
    target: str = "end_effector",
    datasets=None,
    s: TransferSettings = TransferSettings(),
    plan: DataPlan = DataPlan(),
    classifier=None,
    segmenter=None,
    models_dir=None,
    progress=True,
) -> dict:
    """Generate or reuse the target's datasets, run Test C for each task and write the report
    (``out``/report.md, results.json, curve_<task>.png); returns the results {task: ...}."""
    # optional: torch (the learn extra)
    from experiments.transfer_runs import model_config, transfer_task
    from learn.train.device import check_precision

    source, out = O.check_dataset(Path(source), "SOURCE"), Path(out)
    data_dir = Path(datasets) if datasets is not None else out / "data"
    models = Path(models_dir) if models_dir is not None else out / "models"
    O.check_out(out, ("--datasets", data_dir), ("--models", models))
    check_precision(s.device, s.precision)
    if classifier is not None and not s.classification:
        raise ConfigError(
            "--classifier with --no-classification: nothing would use it. Fix: drop one of them"
        )
    tasks = {"classify": classifier} if s.classification else {}
    tasks |= {"segment": segmenter} if s.segmentation or segmenter is not None else {}
    for task, ckpt in tasks.items():
        model_config(task, None if ckpt is None else Path(ckpt), s)
    given = (Path(target) / "dataset.h5").is_file()
    folders = {"source": source, "target": Path(target) if given else data_dir / target}
    part = target
    if given:
        with DatasetReader(folders["target"]) as ds:
            part = ds.attrs.get("part")
        if not part:
            raise ConfigError(
                f"--target {target}: the dataset names no part to simulate its pretraining set on"
            )
    folders["pretrain"] = data_dir / f"{part}_synthetic"
    sizes = {"target": plan.n_target, "pretrain": plan.n_pretrain}
    cfgs = {
        r: generate_config(part, n, dataset_seed(s.seed, r), plan.tiny) for r, n in sizes.items()
    }
    for role in ("pretrain",) if given else ("target", "pretrain"):
        ensure_dataset(folders[role], cfgs[role], plan.workers, progress)
    config = {"datasets": folders, "data_plan": dataclasses.asdict(plan), "classifier": classifier}
    config |= {"segmenter": segmenter} | dataclasses.asdict(s)
    rep = Report("transfer", out, seed=s.seed, config=config)
    results = {
        task: transfer_task(task, *folders.values(), models, s, ckpt and Path(ckpt), progress)
        for task, ckpt in tasks.items()
    }
    rep.section("Setup", describe(folders) + "\n\n" + recipe_text(s))
    for task, res in results.items():
        write_task(rep, task, res)
    results["report"] = str(rep.write(results))
    return results


def describe(folders: dict[str, Path]) -> str:
    """Markdown list of the datasets used and what sets them apart."""
    lines = []
    for role, folder in folders.items():
        with DatasetReader(folder) as ds:
            n_hand, (h, w) = int(ds["is_hand"][:].sum()), ds.image.shape[1:]
            what = f"part {ds.attrs.get('part')}, {len(ds)} samples ({n_hand} hands)"
            lines.append(f"- {role}: `{folder}`: {what}, seed {ds.attrs.get('seed')}, {h}×{w} px")
    return "\n".join(lines) + (
        "\n\nPretraining samples whose object or body-part instance is in the target's test "
        "split are left out (an instance depends on its id alone, in every synthetic set)."
    )


def recipe_text(s: TransferSettings) -> str:
    """How the models were trained, in words."""
    text = (
        f"Fine-tuning (Test C recipe): SGD, lr 0.01 halved after {s.halved_after} "
        f"of {s.finetune_epochs} epochs (paper: after 60 of 120), batch 128, lr × 0.1 on the "
        "first two convolutions (not from scratch), the paper's flips, no validation (the last "
        "weights are scored), the arch preset's loss. Models trained here from scratch (the "
        f"source model unless given, the synthetic one): the arch preset for {s.pretrain_epochs} "
        f"epoch(s), flips {'on' if s.pretrain_flips else 'off'}, the best epoch on a "
        "subject-disjoint validation part. Curve subsets: nested, class-balanced random "
        "prefixes of the target's train split. SegNet trains and is scored on hand samples "
        f"only. Training forward passes in {s.precision}."
    )
    if s.finetune_epochs < 120 or s.pretrain_epochs < 80:
        text += (
            "\n\n**Shortened run**: networks this briefly trained stay near chance, so these "
            "scores test the pipeline, not the method."
        )
    return text


def scores_table(task: str, rows: list[tuple[str, dict]]) -> str:
    """Our scores (%) beside the paper's (unknown to us), in the layout of Tables 15 and 16."""
    keys = {"accuracy": "accuracy"} if task == "classify" else SEG_LABELS
    head = ["model"] + [f"{h} % ({who})" for who in ("ours", "paper") for h in keys.values()]
    body = [[n, *(100 * r["metrics"][k] for k in keys), *([None] * len(keys))] for n, r in rows]
    return markdown_table(head, body)


def curve_chart(res: dict, key: str, label: str, what: str):
    """Score % against N (log x) per start, the zero-shot scores as dashed lines."""
    from matplotlib.figure import Figure  # start-up time: matplotlib

    fig = Figure(figsize=(7, 4.5), layout="constrained")
    ax = fig.subplots()
    for i, (name, points) in enumerate(res["curve"].items()):
        n, y = [p["n"] for p in points], [100 * p["metrics"][key] for p in points]
        ax.plot(n, y, "os^D"[i] + "-", c=f"C{i}", label=f"fine-tuned from {name} (ours)")
    for i, (name, r) in enumerate(res["zero_shot"].items()):
        y = 100 * r["metrics"][key]
        ax.axhline(y, c=f"C{i + 1}", ls="--", lw=1, label=f"{name} model, zero-shot (ours)")
    sizes = [p["n"] for p in res["curve"]["scratch"]]
    ax.set_xscale("log")
    ax.set_xticks(sizes, [str(n) for n in sizes])
    ax.minorticks_off()
    ax.set_xlabel(f"target training {what} N (log scale)")
    ax.set_ylabel(f"test {label}, %")
    ax.set_title(f"Test C learning curve: {label} on the target's test split")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    return fig


def write_task(rep, task: str, res: dict) -> None:
    """Tables 15 and 16, the zero-shot confusions and the learning curve of one task."""
    from learn.evaluate.report import confusion_markdown  # optional: torch (the learn extra)

    title = "Classification" if task == "classify" else "Segmentation"
    key, label = ("accuracy", "accuracy") if task == "classify" else ("mean_iou", "mean IoU")
    what = "samples" if task == "classify" else "hand samples"  # segmenters see hands only
    zero = [(ZERO_SHOT[k], r) for k, r in res["zero_shot"].items()]
    text = f"{res['n_test']} target test {what}, resized to {res['model']['input_size']} px"
    if "canvas_mm" in res:
        h, w = res["canvas_mm"]
        text += f" (the 'at its scale' rows: first centred on a {h:g} × {w:g} mm canvas)"
    text += ".\n\n" + scores_table(task, zero)
    for name, r in zero:
        cm = confusion_markdown(np.array(r["cm"]), tuple(res["class_names"]))
        text += f"\n\n{name}, % of each true class:\n\n{cm}"
    rep.section(f"{title}: zero-shot on the target (paper: Table 15)", text)
    ft = [(FINETUNED[k], points[-1]) for k, points in res["curve"].items()]
    title_16 = f"{title}: fine-tuned on {res['n_train']} target {what} (paper: Table 16)"
    rep.section(title_16, scores_table(task, ft))
    sizes, starts = [p["n"] for p in res["curve"]["scratch"]], list(res["curve"])
    body = [
        [n, *(100 * res["curve"][i][k]["metrics"][key] for i in starts)]
        for k, n in enumerate(sizes)
    ]
    head = [f"N (target train {what})", *(f"from {i} %" for i in starts)]
    rep.section(f"{title}: learning curve ({label} %)", markdown_table(head, body))
    caption = (
        f"Test {label} against the number of target training {what}, fine-tuned with the "
        "Test C recipe; dashed: zero-shot. The paper's Test C numbers are unknown to us."
    )
    rep.figure(curve_chart(res, key, label, what), f"curve_{task}.png", caption)


SourceArg = Annotated[
    Path, typer.Argument(metavar="DATASET", help="Dataset folder of the source part (forearm).")
]
TargetOpt = O.opt(str, "Part to simulate, or a dataset folder.")
CurveOpt = O.opt(str | None, "Curve points (samples; 10,30,100,300).")
KeepScaleOpt = O.opt(bool, "Also the source model at its own mm/px.", "--keep-scale")


@experiment("transfer")
def transfer(
    source: SourceArg,
    out: O.OutOpt,
    target: TargetOpt = "end_effector",
    datasets: O.DatasetsOpt = None,
    quick: O.QuickOpt = False,
    seed: O.SeedOpt = 0,
    classifier: O.ClassifierOpt = None,
    segmenter: O.SegmenterOpt = None,
    segmentation: O.SegmentationOpt = False,
    classification: O.opt(bool, "The classifier.", "--classification/--no-classification") = True,
    epochs: O.opt(int | None, "Fine-tuning epochs (count; default 120).") = None,
    pretrain_epochs: O.opt(int | None, "Epochs from scratch (count; default 80).") = None,
    curve: CurveOpt = None,
    keep_scale: KeepScaleOpt = False,
    precision: O.opt(str, "Training number format: fp32 or bf16.") = "fp32",
    workers: O.opt(int, "Generation processes (count).") = 1,
    models: O.ModelsOpt = None,
    threads: O.ThreadsOpt = 2,
    device: O.DeviceOpt = "cpu",
    progress: O.ProgressOpt = True,
) -> Path:
    """Test C: a model moved to another skin part, as the paper's Tables 15-16.

    The source model on the target part zero-shot and fine-tuned, a model pretrained on
    synthetic data of the target part, and the learning curve of fine-tuning.

    --quick: 200 + 400 samples generated, 3 + 1 epochs, curve at N = 10, 30 and all.
    """
    O.check_at_least("--workers", workers)
    changes = {"finetune_epochs": epochs, "pretrain_epochs": pretrain_epochs}
    changes = {
        k: v
        for k, v in (
            changes | {"curve_sizes": O.parse_list("--curve", curve, int, ("all",))}
        ).items()
        if v is not None
    }
    flags = {"seed": seed, "segmentation": segmentation or segmenter is not None}
    flags |= {"classification": classification, "precision": precision, "keep_scale": keep_scale}
    s = dataclasses.replace(
        QUICK if quick else TransferSettings(), device=device, threads=threads, **flags, **changes
    )
    plan = dataclasses.replace(QUICK_DATA if quick else DataPlan(), workers=workers)
    kw = {
        "classifier": classifier,
        "segmenter": segmenter,
        "models_dir": models,
        "progress": progress,
    }
    return Path(
        run_transfer_experiment(
            source, out, target=target, datasets=datasets, s=s, plan=plan, **kw
        )["report"]
    )
