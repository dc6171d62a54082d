"""`handskin experiment pareto`: score against CPU time per image for every model, width and
input size, with the Pareto front and the paper's published points (issue #7, part 5).

Variants, each scored on the dataset's test split and timed at batch 1 on 1 CPU thread:
- classification: HandsNet at every ``sizes`` ("full" = the dataset's stored image size), the
  VGG16-style classifier at every ``widths`` (at the main classifier's size; width 1.0 is
  GPU-only at our budgets and runs only when asked), BoVW, and VGG16 features + linear SVM;
- segmentation: SegNet and FCN-16s at every ``seg_widths`` (main segmenter's size), and the main
  segmenter's architecture and width at every ``seg_sizes``.
The main models come from ``--classifier`` / ``--segmenter`` (used as they are) or are trained
here like every other variant: SGD for a wall-clock budget (``budget_min`` per variant, checked
between steps; at most the preset's epochs), at the preset's first-phase learning rate, without
validation (the last weights are kept), variants at other sizes starting from the main model's
weights where shapes match (``warm_start``). Budgets are short and stated, so the scores of slow
variants are lower bounds. Trained variants are kept in ``models_dir/<key>/best.pt`` and reused
by a rerun with the same configuration and budget.
"""

from __future__ import annotations

import dataclasses
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

import typer

from tactile.errors import ConfigError, DataError, HandskinError
from tactile.resize import NET_SIZE

NAMES = {"handsnet": "HandsNet", "vgg16": "VGG16", "segnet": "SegNet", "fcn16s": "FCN-16s"}
TASK = {"handsnet": "classify", "vgg16": "classify", "segnet": "segment", "fcn16s": "segment"}


def parse_size(text: str, full_hw: tuple[int, int]) -> tuple[int, int]:
    """``"68x100"`` → (68, 100) px; ``"full"`` → ``full_hw``. ConfigError otherwise."""
    if text == "full":
        return (int(full_hw[0]), int(full_hw[1]))
    match = re.fullmatch(r"(\d+)[x×](\d+)", text.strip())
    if not match or min(int(match[1]), int(match[2])) < 1:
        raise ConfigError(
            f"size {text!r}: expected <height>x<width> in pixels (e.g. 68x100) or 'full'"
        )
    return (int(match[1]), int(match[2]))


@dataclass(frozen=True)
class ParetoSettings:
    """What the pareto experiment runs; sizes are ``"<h>x<w>"`` pixels or ``"full"``."""

    sizes: tuple[str, ...] = ("34x50", "68x100", "136x200", "full")  # HandsNet inputs, px
    widths: tuple[float, ...] = (0.125, 0.25)  # VGG16 classifier channel multipliers
    seg_widths: tuple[float, ...] = (0.25, 0.5)  # SegNet and FCN-16s channel multipliers
    # main segmenter's inputs, px; "full" is left out: ~1 s/image at width 0.5 on this CPU
    seg_sizes: tuple[str, ...] = ("34x50", "68x100", "136x200")
    budget_min: float = 2.0  # training wall-clock budget per trained variant, minutes
    max_steps: int | None = None  # optional cap on SGD steps per variant (count)
    max_train: int | None = None  # train samples used (seeded subset; None: the whole split)
    max_test: int | None = 500  # test samples scored per variant (seeded subset; None: all)
    time_runs: int = 30  # timed batch-1 runs per model after 20 warm-up runs (count)
    warm_start: bool = True  # variants at other sizes start from the main model's weights
    classic: bool = True  # also BoVW and VGG16 features + SVM
    segmentation: bool = True  # also the segmentation variants
    seed: int = 0  # seed of initialisation, shuffling and subsets
    threads: int = 2  # torch CPU threads while training (timing always uses 1)

    def __post_init__(self) -> None:
        for name in ("widths", "seg_widths"):
            if any(not 0 < w <= 4 for w in getattr(self, name)):
                raise ConfigError(
                    f"{name} must lie in (0, 4] (channel multipliers), got {getattr(self, name)}"
                )
        for size in (*self.sizes, *self.seg_sizes):
            parse_size(size, (1, 1))
        if self.budget_min <= 0 or self.time_runs < 1 or self.threads < 1:
            raise ConfigError("budget_min > 0 (minutes), time_runs >= 1, threads >= 1 needed")
        for name in ("max_steps", "max_train", "max_test"):
            if getattr(self, name) is not None and getattr(self, name) < 1:
                raise ConfigError(f"{name} must be >= 1 (count) or unset")


#: The full setting (≲ 45 min on 2 shared cores with the main models given) and the quick one.
FULL = ParetoSettings()
QUICK = ParetoSettings(
    sizes=("34x50", "68x100"),
    widths=(0.125,),
    seg_widths=(0.25,),
    seg_sizes=("68x100",),
    budget_min=0.4,
    max_train=1000,
    max_test=300,
    time_runs=10,
)


@dataclass(frozen=True)
class Variant:
    """One network to score: architecture, input (h, w) px, width; given or trained here."""

    arch: str
    size: tuple[int, int]
    width: float | None = None
    checkpoint: Path | None = None  # a given checkpoint, used as is
    warm: bool = False  # start training from the main model of its task
    tag: str | None = None  # an --also checkpoint: its run folder's name, told apart by it

    @property
    def task(self) -> str:
        return TASK[self.arch]

    @property
    def key(self) -> str:
        """Folder name under models_dir, e.g. ``segnet-68x100-w0.5``."""
        width = "" if self.width is None else f"-w{self.width:g}"
        tag = "" if self.tag is None else f"-given-{self.tag}"
        return f"{self.arch}-{self.size[0]}x{self.size[1]}{width}{tag}"

    @property
    def name(self) -> str:
        width = "" if self.width is None else f" w{self.width:g}"
        tag = "" if self.tag is None else f" ({self.tag})"
        return f"{NAMES[self.arch]}{width} {self.size[0]}×{self.size[1]}{tag}"


def given_variant(checkpoint: str | Path, tag: str | None = None) -> Variant:
    """The variant of a checkpoint used as is: its architecture, width and input size."""
    from learn.checkpoint import load_checkpoint
    from learn.train import run_from_dict

    model = run_from_dict(load_checkpoint(checkpoint)["config"]).model
    width = None if model.arch == "handsnet" else model.width
    return Variant(model.arch, tuple(model.input_size), width, checkpoint=Path(checkpoint), tag=tag)


def main_variant(checkpoint: Path | None, arch: str, width: float | None) -> Variant:
    """The main model: a given checkpoint's architecture, width and size (of ``arch``'s task),
    or ``arch`` at ``width`` and 68 × 100 px."""
    if checkpoint is None:
        return Variant(arch, NET_SIZE, width)
    v = given_variant(checkpoint)
    if v.task != TASK[arch]:
        option = "--classifier" if TASK[arch] == "classify" else "--segmenter"
        raise ConfigError(
            f"{option} {checkpoint} is a {v.arch} checkpoint; give a "
            f"{'classifier' if TASK[arch] == 'classify' else 'segmenter'}"
        )
    return v


def also_variants(paths: list[Path], segment: bool) -> list[Variant]:
    """Variants of ``--also`` checkpoints (any architecture), used as they are and named after
    their run folders. DataError for a missing file; ConfigError for a segmenter when
    segmentation is off, or two that would share a name."""
    out = [given_variant(p, Path(p).parent.name or Path(p).stem) for p in paths]
    for v in out:
        if v.task == "segment" and not segment:
            raise ConfigError(
                f"--also {v.checkpoint} is a {v.arch} checkpoint, but segmentation "
                "is off (--no-segmentation, or the dataset has no label images). "
                "Fix: drop it or turn segmentation on"
            )
    if len({v.key for v in out}) < len(out):
        raise ConfigError(
            "two --also checkpoints of one architecture, width and size share a "
            "run folder name. Fix: give each its own folder"
        )
    return out


def plan_variants(
    s: ParetoSettings,
    full_hw: tuple[int, int],
    clf: Variant,
    seg: Variant | None,
    also: list[Variant] = (),
) -> list[Variant]:
    """Every variant without duplicates (by key): per task the main model first, then the
    others by input area (so tensors of one size are loaded once and then released); ``also``
    (given checkpoints) are drawn beside the variants of their architecture."""
    from learn.models import create_model

    out = [clf, *also]
    for size in s.sizes:
        out.append(Variant("handsnet", parse_size(size, full_hw), warm=clf.arch == "handsnet"))
        create_model("handsnet", input_size=out[-1].size)  # ConfigError below 24 px, now
    out += [Variant("vgg16", clf.size, w) for w in s.widths]
    if seg is not None:
        out += [seg] + [Variant(a, seg.size, w) for a in ("segnet", "fcn16s") for w in s.seg_widths]
        out += [
            Variant(seg.arch, parse_size(z, full_hw), seg.width, warm=True) for z in s.seg_sizes
        ]
    kept: dict[str, Variant] = {}
    for v in out:
        kept.setdefault(v.key, v)
    rest = sorted(
        (v for v in kept.values() if v not in (clf, seg)),
        key=lambda v: (v.task != "classify", v.size[0] * v.size[1]),
    )
    return [
        clf,
        *(v for v in rest if v.task == "classify"),
        *([seg] if seg else []),
        *(v for v in rest if v.task == "segment"),
    ]


def variant_run(v: Variant, s: ParetoSettings):
    """The preset RunConfig of ``v``'s architecture at its size and width, no validation."""
    from learn.experiments.models import preset_run

    run = preset_run(v.arch, seed=s.seed)
    model = dataclasses.replace(run.model, input_size=v.size, width=v.width or run.model.width)
    return dataclasses.replace(run, model=model, val_fraction=0.0, threads=s.threads)


def check_data(data: Path) -> tuple[tuple[int, int], bool]:
    """(stored image (H, W) px, has label images) of a dataset; DataError when there is none."""
    from learn.folder import is_dataset
    from tactile.dataset.reader import DatasetReader

    if not is_dataset(data):
        raise DataError(
            f"no dataset at {data}. Fix: give --data a dataset folder holding "
            "dataset.h5 (e.g. from handskin generate)"
        )
    with DatasetReader(data) as ds:
        return tuple(ds.image.shape[1:]), "label_image" in ds.fields


def not_run(s: ParetoSettings, segment: bool) -> list[str]:
    """Variants of the issue this configuration leaves out, and why."""
    out = []
    if 1.0 not in s.widths:
        out.append("VGG16 w1 (full VGG16 width): GPU-only at these budgets; add 1.0 to --widths")
    if not segment:
        out.append("segmentation: disabled, or the dataset has no label images")
    elif "full" not in s.seg_sizes:
        out.append(
            "segmenter at the full map: ~1 s/image at width 0.5 on this CPU (training and "
            "scoring exceed the budget); add 'full' to --seg-sizes"
        )
    return out


def run_pareto(
    data: str | Path,
    out: str | Path,
    s: ParetoSettings = FULL,
    *,
    classifier: str | Path | None = None,
    segmenter: str | Path | None = None,
    models_dir: str | Path | None = None,
    also: list[str | Path] = (),
    progress: bool = True,
) -> dict:
    """Score and time every variant; write ``out``/report.md, results.json and the charts
    pareto_classification.png, pareto_segmentation.png. Returns the results dict (``rows``:
    one dict per variant, see ``pareto_plot``). ``also``: more checkpoints scored as they are
    (e.g. a fully trained FCN-16s beside the budgeted one). Inputs are checked before any work."""
    from learn.experiments.pareto_plot import write_report
    from learn.experiments.pareto_train import Runner, classic_rows
    from learn.experiments.report import Report
    from tactile.config import to_dict

    data, out = Path(data), Path(out)
    full_hw, labelled = check_data(data)
    clf = main_variant(None if classifier is None else Path(classifier), "handsnet", None)
    segment = s.segmentation and labelled
    seg = (
        main_variant(
            None if segmenter is None else Path(segmenter), "segnet", max(s.seg_widths, default=0.5)
        )
        if segment
        else None
    )
    given = also_variants(list(also), seg is not None)
    variants = plan_variants(s, full_hw, clf, seg, given)
    config = {
        "data": str(data),
        "classifier": classifier,
        "segmenter": segmenter,
        "also": [str(p) for p in also],
        "full_map_px": full_hw,
        **to_dict(s),
    }
    rep = Report("pareto", out, seed=s.seed, config=config)
    runner = Runner(data, s, Path(models_dir) if models_dir else out / "models", progress)
    rows, vgg = [], None
    for i, v in enumerate(variants):
        row, model = runner.row(v)
        rows.append(row)
        if v.arch == "vgg16" and (vgg is None or v.width > vgg[0]):
            vgg = (v.width, model)
        later = {(w.task, w.size) for w in variants[i + 1 :]}
        here = (v.task, v.size)
        if s.classic and here == ("classify", clf.size) and here not in later:
            rows += classic_rows(runner, clf.size, vgg)
        runner.cache = {k: t for k, t in runner.cache.items() if (k[1], k[2]) in later}
    return write_report(rep, rows, not_run(s, seg is not None), data)


def _csv(text: str | None, kind: type) -> tuple | None:
    if text is None:
        return None
    try:
        return tuple(kind(t.strip()) for t in text.split(",") if t.strip())
    except ValueError:
        raise ConfigError(
            f"cannot read {text!r} as comma-separated {kind.__name__} values; "
            "write e.g. 0.125,0.25 or 34x50,68x100"
        ) from None


def _opt(kind, help_text: str, *names: str):
    return Annotated[kind, typer.Option(*names, help=help_text)]


def pareto_command(
    out: _opt(Path, "Experiment folder (path): report.md, results.json, PNG charts, models/."),
    data: _opt(Path, "Dataset folder (path) holding dataset.h5, e.g. a forearm dataset."),
    quick: _opt(
        bool,
        "Small version (minutes): HandsNet 34x50 and 68x100, VGG16 w0.125, "
        "SegNet/FCN w0.25, 0.4 min per variant, 1000 train / 300 test samples.",
    ) = False,
    seed: _opt(int, "Seed (integer) of initialisation, shuffling and subsets.") = 0,
    classifier: _opt(Path | None, "Main classifier checkpoint (.pt file), used as is.") = None,
    segmenter: _opt(Path | None, "Main segmenter checkpoint (.pt file), used as is.") = None,
    also: _opt(
        list[Path] | None,
        "More checkpoints (.pt files, any architecture) scored as they "
        "are and named after their run folder, e.g. a fully trained FCN-16s; repeat the "
        "option for several.",
    ) = None,
    models: _opt(
        Path | None,
        "Folder (path) of the variants trained here; default OUT/models; "
        "reused by a rerun with the same budget.",
    ) = None,
    sizes: _opt(
        str | None,
        "HandsNet input sizes: comma-separated <h>x<w> in pixels, or "
        "'full' (the dataset's image size). Default 34x50,68x100,136x200,full.",
    ) = None,
    widths: _opt(
        str | None,
        "VGG16 classifier widths: comma-separated channel multipliers "
        "(1.0 = VGG16's 64..512 channels). Default 0.125,0.25.",
    ) = None,
    seg_widths: _opt(
        str | None,
        "SegNet and FCN-16s widths: comma-separated channel multipliers. Default 0.25,0.5.",
    ) = None,
    seg_sizes: _opt(
        str | None,
        "Main segmenter's input sizes: <h>x<w> pixels or 'full'. Default 34x50,68x100,136x200.",
    ) = None,
    budget_min: _opt(
        float | None,
        "Training budget per trained variant, wall-clock minutes "
        "on the CPU (default 2.0; quick 0.4).",
    ) = None,
    max_steps: _opt(int | None, "Cap on SGD steps per trained variant (count).") = None,
    max_train: _opt(int | None, "Train samples used (count, seeded subset; 0 = all).") = None,
    max_test: _opt(
        int | None,
        "Test samples scored per variant (count, seeded subset; 0 = all; default 500, quick 300).",
    ) = None,
    time_runs: _opt(
        int | None, "Timed batch-1 runs per model after 20 warm-up runs (count)."
    ) = None,
    warm_start: _opt(
        bool | None,
        "Variants at other sizes start from the main model's weights (shapes that match).",
        "--warm-start/--no-warm-start",
    ) = None,
    classic: _opt(
        bool | None, "Also BoVW and VGG16 features + SVM.", "--classic/--no-classic"
    ) = None,
    segmentation: _opt(
        bool | None, "Also the segmentation variants.", "--segmentation/--no-segmentation"
    ) = None,
    progress: _opt(bool, "Show progress bars.") = True,
) -> None:
    """Accuracy / mIoU against CPU ms per image for every model, width and input size."""
    from learn.cli import _fail

    try:
        given = {
            "sizes": _csv(sizes, str),
            "widths": _csv(widths, float),
            "seg_widths": _csv(seg_widths, float),
            "seg_sizes": _csv(seg_sizes, str),
            "budget_min": budget_min,
            "max_steps": max_steps,
            "time_runs": time_runs,
            "warm_start": warm_start,
            "classic": classic,
            "segmentation": segmentation,
            "seed": seed,
        }
        changes = {k: v for k, v in given.items() if v is not None}
        for key, value in (("max_train", max_train), ("max_test", max_test)):
            if value is not None:
                changes[key] = value or None  # 0 = all samples
        settings = dataclasses.replace(QUICK if quick else FULL, **changes)
        result = run_pareto(
            data,
            out,
            settings,
            classifier=classifier,
            segmenter=segmenter,
            models_dir=models,
            also=also or [],
            progress=progress,
        )
    except (HandskinError, KeyError) as err:
        raise _fail(err) from err
    typer.echo(f"report written to {result['report']}")


def register(app) -> None:
    """Add ``pareto`` to `handskin experiment`."""
    from learn.cli import _needs_torch

    app.command("pareto")(_needs_torch(pareto_command))
