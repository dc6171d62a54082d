"""Shared setup of the robustness experiments: run sizes, networks (given or trained), test frames,
and the report's setup text.

    scale = QUICK.changed(patterns=3, test_samples=None, seg_samples=None)
    models, info, frames, agreement = prepare(data, out, scale, seed, None, None, None, 2, True)
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from pathlib import Path

from learn.experiments.robustness_models import FULL_PLAN, QUICK_PLAN, TrainPlan
from tactile.errors import ConfigError

N_SPOTS = (1, 2, 3, 4)  # Test A: blind spots per pattern (paper)
RADII_MM = (10.0, 20.0, 30.0, 40.0)  # Test A: spot radius, mm (paper)
FRACTIONS = (0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7)  # Test B: share of taxels removed (paper)


@dataclass(frozen=True)
class Scale:
    """Sizes of a robustness run.

    n_patterns : random patterns per condition. n_classify : test samples classified (None:
    all). n_segment : test hand samples segmented (a fixed-seed subset). n_spots, radii_mm :
    Test A grid (count, mm). fractions : Test B shares of taxels removed (0 = intact map).
    plan : how networks not given are trained.
    """

    n_patterns: int
    n_classify: int | None
    n_segment: int
    n_spots: tuple[int, ...] = N_SPOTS
    radii_mm: tuple[float, ...] = RADII_MM
    fractions: tuple[float, ...] = FRACTIONS
    plan: TrainPlan = FULL_PLAN

    def __post_init__(self) -> None:
        if self.n_patterns < 1 or self.n_segment < 1:
            raise ConfigError(
                f"patterns and segmented samples must be >= 1, got "
                f"{self.n_patterns} and {self.n_segment}"
            )
        if self.n_classify is not None and self.n_classify < 1:
            raise ConfigError(f"classified test samples must be >= 1, got {self.n_classify}")
        if min(self.n_spots) < 0 or min(self.radii_mm) < 0:
            raise ConfigError("blind spots: counts and radii (mm) must be >= 0")
        if not all(0.0 <= f < 1.0 for f in self.fractions):
            raise ConfigError(f"removed shares must lie in [0, 1), got {self.fractions}")

    def changed(
        self,
        patterns: int | None,
        test_samples: int | None,
        seg_samples: int | None,
        device: str | None = None,
    ) -> Scale:
        """A copy with the command line's counts and training device (None keeps a field)."""
        new = {"n_patterns": patterns, "n_classify": test_samples, "n_segment": seg_samples}
        plan = self.plan if device is None else dataclasses.replace(self.plan, device=device)
        return dataclasses.replace(
            self, plan=plan, **{k: v for k, v in new.items() if v is not None}
        )


FULL = Scale(n_patterns=10, n_classify=None, n_segment=200)
QUICK = Scale(n_patterns=2, n_classify=300, n_segment=40, plan=QUICK_PLAN)


def networks(
    data, models_dir: Path, scale: Scale, seed: int, classifier, segmenter, progress: bool
) -> tuple[list, list[dict]]:
    """([classifier, segmenter] as Predictors, a description of each): given or trained."""
    from learn.checkpoint import load_checkpoint
    from learn.evaluate import ARCH_LABEL
    from learn.experiments.robustness_eval import Predictor
    from learn.experiments.robustness_models import resolve_model

    out, info = [], []
    for arch, given in (("handsnet", classifier), ("segnet", segmenter)):
        path = resolve_model(arch, data, models_dir, given, scale.plan, seed, progress)
        ckpt = load_checkpoint(path)
        pred = Predictor.load(ARCH_LABEL.get(ckpt["config"]["model"]["arch"], arch), path)
        out.append(pred)
        info.append(
            {
                "name": pred.name,
                "checkpoint": str(path),
                "given": given is not None,
                "epochs": ckpt["epoch"],
                "model": ckpt["config"]["model"],
                "data": ckpt.get("data"),
            }
        )
    return out, info


def check_checkpoint(path, task: str) -> None:
    """DataError/ConfigError unless ``path`` is a checkpoint of a ``task`` network."""
    from learn.checkpoint import load_checkpoint
    from learn.train import TASK_OF_ARCH

    arch = load_checkpoint(path)["config"]["model"]["arch"]
    if TASK_OF_ARCH.get(arch) != task:
        want = (
            "classifier (handsnet, vgg16)" if task == "classify" else "segmenter (segnet, fcn16s)"
        )
        raise ConfigError(f"{path} holds a {arch} network; give a {want} checkpoint")


def setup_markdown(data, frames, agreement: dict, info: list[dict], scale: Scale) -> str:
    """The report's setup section: data, subsets, networks, how images were regenerated."""
    n_seg, n_clf = len(frames.segment), len(frames.classify)
    lines = [
        f"Dataset `{data}`: test split of {frames.n_split} samples; classification on "
        f"{'all ' if n_clf == frames.n_split else 'a fixed-seed subset of '}{n_clf}, "
        f"segmentation on a fixed-seed subset of {n_seg} test hand samples (both drawn from "
        "--seed). Every pattern is drawn from --seed; its index is in results.json.",
        "",
        "Images are regenerated from the raw readings (`DatasetReader.pressure_from_raw`: "
        "baseline, drift and the generator's 3-sigma noise floor removed, over the nominal gain) "
        "through the corrupted map with `TactileMap.image`; label images with "
        "`tactile.labels.label_image`. Against "
        f"the stored images at zero corruption: {100 * agreement['identical_images']:.1f} % "
        f"identical, {100 * agreement['differing_pixels']:.3f} % of pixels differ (at most "
        f"{agreement['max_grey_difference']} grey levels), "
        f"{100 * agreement['differing_label_pixels']:.4f} % of label pixels differ."
        + ("" if agreement["identical_images"] == 1.0 else DRIFT_NOTE),
        "",
    ]
    fast = ", ".join(f"{k} {100 * v:.2f} %" for k, v in agreement.get("fast_path", {}).items())
    lines += [
        "Networks run with batch norms folded into the convolutions (channels-last, "
        "`learn.models.prepare_for_inference`), batches of 64 under `torch.no_grad`; their "
        "predictions equal the eval-mode networks' on up to 256 regenerated test images "
        f"(images or pixels): {fast}.",
        "",
    ]
    for m in info:
        how = "given" if m["given"] else f"trained here ({scale.plan})"
        lines.append(
            f"- {m['name']}: `{m['checkpoint']}` ({how}; best epoch {m['epochs']}; "
            f"input {tuple(m['model']['input_size'])} px, width "
            f"{m['model'].get('width')})"
        )
    return "\n".join(lines)


DRIFT_NOTE = (
    " Datasets written before the generator stored the per-taxel baseline drift (root attr "
    "`skin_drift_counts_per_s`) are regenerated without it: a frame's largest reading can move by "
    "a count or so (one grey level) and readings near the noise floor may cross it. "
    "Regenerating the dataset with this version stores it."
)


def baseline_table(cms: dict, models) -> str:
    """Scores (%) on the regenerated, uncorrupted test images."""
    from learn.experiments.report import markdown_table
    from learn.experiments.robustness_eval import scores_pct

    rows = [
        [m.name, ", ".join(f"{k} {v:.2f}" for k, v in scores_pct(cms[m.name], m.task).items())]
        for m in models
    ]
    return markdown_table(["network", "scores (%)"], rows)


@dataclass
class Prepared:
    """What every robustness experiment starts from: networks (Predictors) and their
    description, the test frames, their agreement with the stored images, and the minutes
    spent so far by phase."""

    models: list
    info: list[dict]
    frames: object
    agreement: dict
    minutes: dict[str, float]


def check_inputs(data, classifier, segmenter, threads: int, device: str = "cpu") -> None:
    """Fail before any work: the dataset's test split, the checkpoints' tasks, threads, the
    training device."""
    from learn.device import check_device
    from learn.experiments.robustness_data import load_frames

    if threads < 1:
        raise ConfigError(f"threads must be >= 1, got {threads}")
    check_device(device)
    load_frames(data, "test", n_classify=1, n_segment=1)
    for path, task in ((classifier, "classify"), (segmenter, "segment")):
        if path is not None:
            check_checkpoint(path, task)


def prepare(
    data,
    out,
    scale: Scale,
    seed: int,
    classifier,
    segmenter,
    models_dir,
    threads: int,
    progress: bool,
) -> Prepared:
    """Load or train the networks and read the test frames (after :func:`check_inputs`)."""
    import torch

    from learn.experiments.robustness_data import load_frames, stored_agreement
    from learn.experiments.robustness_eval import fast_path_agreement

    torch.set_num_threads(threads)
    models_dir = Path(models_dir) if models_dir is not None else Path(out) / "models"
    tic = time.perf_counter()
    models, info = networks(data, models_dir, scale, seed, classifier, segmenter, progress)
    toc = time.perf_counter()
    frames = load_frames(
        data, "test", n_classify=scale.n_classify, n_segment=scale.n_segment, seed=seed
    )
    agreement = stored_agreement(data, frames)
    agreement["fast_path"] = fast_path_agreement(frames, models)
    minutes = {"networks": (toc - tic) / 60, "frames": (time.perf_counter() - toc) / 60}
    return Prepared(models, info, frames, agreement, minutes)


def timing_line(minutes: dict[str, float]) -> str:
    """'Time by phase: networks 1.0 min, ...' for the report."""
    return "Time by phase: " + ", ".join(f"{k} {v:.1f} min" for k, v in minutes.items()) + "."


def config_of(data, scale: Scale, classifier, segmenter, threads: int) -> dict:
    return {
        "data": str(data),
        "scale": dataclasses.asdict(scale),
        "threads": threads,
        "classifier": None if classifier is None else str(classifier),
        "segmenter": None if segmenter is None else str(segmenter),
    }
