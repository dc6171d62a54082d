"""`handskin experiment pareto`: score against CPU time per image for every model, width and
input size, with the Pareto front and the paper's published points.

    run_pareto("data/forearm", "out/pareto", QUICK, classifier="runs/handsnet/best.pt")

Variants, each scored on the dataset's test split and timed at batch 1 on 1 CPU thread:
- classification: HandsNet at every ``sizes`` ("full" = the dataset's stored image size), the
  VGG16-style classifier at every ``widths`` (at the main classifier's size), BoVW, and VGG16
  features + a linear SVM;
- segmentation: SegNet and FCN-16s at every ``seg_widths`` (at the main segmenter's size), and
  the main segmenter's architecture and width at every ``seg_sizes``.
The main models come from ``--classifier`` / ``--segmenter`` (used as they are) or are trained
here like every other variant: SGD for a wall-clock budget (``budget_min`` per variant, checked
between steps; at most the preset's epochs) at the preset's first-phase learning rate, without
validation (the last weights are kept); variants at other sizes start from the main model's
weights where shapes match. Trained variants are kept in ``models_dir/<key>/best.pt`` and
reused by a rerun with the same configuration and budget.
"""

from __future__ import annotations

import dataclasses
import re
from dataclasses import dataclass
from pathlib import Path

from experiments import experiment
from experiments import options as O
from tactile.errors import ConfigError

NAMES = {"handsnet": "HandsNet", "vgg16": "VGG16", "segnet": "SegNet", "fcn16s": "FCN-16s"}
TASK = {"handsnet": "classify", "vgg16": "classify", "segnet": "segment", "fcn16s": "segment"}
ROLE = {"classify": "classifier", "segment": "segmenter"}
NET_SIZE = (68, 100)  # (h, w) px: the paper's network input, of main models trained here


def parse_size(text: str, full_hw: tuple[int, int]) -> tuple[int, int]:
    """``"68x100"`` -> (68, 100) px; ``"full"`` -> ``full_hw``. ConfigError otherwise."""
    if text == "full":
        return (int(full_hw[0]), int(full_hw[1]))
    match = re.fullmatch(r"(\d+)[x×](\d+)", text.strip())
    if not match or min(int(match[1]), int(match[2])) < 1:
        raise ConfigError(f"size {text!r}: expected <height>x<width> px (e.g. 68x100) or full")
    return (int(match[1]), int(match[2]))


@dataclass(frozen=True)
class ParetoSettings:
    """What the pareto experiment runs; sizes are ``"<h>x<w>"`` pixels or ``"full"``."""

    sizes: tuple[str, ...] = ("34x50", "68x100", "136x200", "full")  # HandsNet inputs, px
    widths: tuple[float, ...] = (0.125, 0.25)  # VGG16 classifier channel multipliers
    seg_widths: tuple[float, ...] = (0.25, 0.5)  # SegNet and FCN-16s channel multipliers
    seg_sizes: tuple[str, ...] = ("34x50", "68x100", "136x200")  # main segmenter's inputs, px
    budget_min: float = 2.0  # training wall-clock budget per trained variant, minutes
    max_steps: int | None = None  # a cap on SGD steps per variant (count; None: the budget's)
    max_train: int | None = None  # train samples used (a seeded subset; None: the whole split)
    max_test: int | None = 500  # test samples scored per variant (a seeded subset; None: all)
    time_runs: int = 30  # timed batch-1 runs per model after 20 warm-up runs (count)
    classic: bool = True  # also BoVW and VGG16 features + SVM
    segmentation: bool = True  # also the segmentation variants
    seed: int = 0  # seed of initialisation, shuffling and subsets
    threads: int = 2  # torch CPU threads while training (timing always uses 1)

    def __post_init__(self) -> None:
        for name in ("widths", "seg_widths"):
            if any(not 0 < w <= 4 for w in getattr(self, name)):
                raise ConfigError(f"{flag(name)} {getattr(self, name)}: widths must lie in (0, 4]")
        for size in (*self.sizes, *self.seg_sizes):
            parse_size(size, (1, 1))
        if not self.budget_min > 0:
            raise ConfigError(f"--budget-min {self.budget_min} is out of range; allowed > 0 min")
        for name in ("max_steps", "max_train", "max_test", "time_runs", "threads"):
            O.check_at_least(flag(name), getattr(self, name))


def flag(field_name: str) -> str:
    """The command-line flag of a ParetoSettings field, or the field's name when it has none."""
    has_flag = field_name in ("widths", "max_train", "max_test", "threads")
    return f"--{field_name.replace('_', '-')}" if has_flag else f"ParetoSettings.{field_name}"


FULL = ParetoSettings()
QUICK = dataclasses.replace(
    FULL, sizes=("34x50", "68x100"), widths=(0.125,), seg_widths=(0.25,), seg_sizes=("68x100",)
)
QUICK = dataclasses.replace(QUICK, budget_min=0.4, max_train=1000, max_test=300, time_runs=10)


@dataclass(frozen=True)
class Variant:
    """One network to score: architecture, input (h, w) px, width; given or trained here."""

    arch: str
    size: tuple[int, int]
    width: float | None = None
    checkpoint: Path | None = None  # a given checkpoint, used as is
    warm: bool = False  # start training from the main model of its task

    @property
    def task(self) -> str:
        return TASK[self.arch]

    @property
    def key(self) -> str:
        """Folder name under models_dir, e.g. ``segnet-68x100-w0.5``."""
        width = "" if self.width is None else f"-w{self.width:g}"
        return f"{self.arch}-{self.size[0]}x{self.size[1]}{width}"

    @property
    def name(self) -> str:
        width = "" if self.width is None else f" w{self.width:g}"
        return f"{NAMES[self.arch]}{width} {self.size[0]}×{self.size[1]}"


def plan_variants(s: ParetoSettings, full_hw, clf: Variant, seg: Variant | None) -> list[Variant]:
    """Every variant once (by key): per task the main model first, then the others by input
    area (so tensors of one size are loaded once, then released)."""
    out = [
        Variant("handsnet", parse_size(z, full_hw), warm=clf.arch == "handsnet") for z in s.sizes
    ]
    out += [Variant("vgg16", clf.size, w) for w in s.widths]
    if seg is not None:
        out += [Variant(a, seg.size, w) for a in ("segnet", "fcn16s") for w in s.seg_widths]
        out += [
            Variant(seg.arch, parse_size(z, full_hw), seg.width, warm=True) for z in s.seg_sizes
        ]
    mains = [clf] if seg is None else [clf, seg]
    rest: dict[str, Variant] = {}
    for v in out:
        if v.key not in {m.key for m in mains}:
            rest.setdefault(v.key, v)
    rest = sorted(rest.values(), key=lambda v: v.size[0] * v.size[1])
    clfs, segs = ([v for v in rest if v.task == t] for t in ("classify", "segment"))
    return [clf, *clfs, *mains[1:], *segs]


def run_pareto(
    data,
    out,
    s: ParetoSettings = FULL,
    *,
    classifier=None,
    segmenter=None,
    models_dir=None,
    progress=True,
) -> dict:
    """Score and time every variant; write ``out``/report.md, results.json and the charts
    pareto_classification.png, pareto_segmentation.png. Returns the results dict (``rows``: one
    dict per variant). Every input is checked before any work."""
    # optional: torch (the learn extra)
    from experiments.pareto_front import write_report
    from experiments.pareto_runs import Runner, classic_rows, model_of
    from experiments.report import Report
    from learn.models import create_model
    from tactile.config import to_dict
    from tactile.dataset.reader import DatasetReader

    def given(flag: str, path, task: str) -> Variant:
        model = model_of(Path(path))
        if TASK[model.arch] != task:
            raise ConfigError(f"{flag} {path} holds a {model.arch} network; give a {ROLE[task]}")
        width = None if model.arch == "handsnet" else model.width
        return Variant(model.arch, tuple(model.input_size), width, Path(path))

    data, out = O.check_dataset(Path(data)), Path(out)
    O.check_out(out, ("--models", models_dir))
    with DatasetReader(data) as ds:
        full_hw, labelled = tuple(ds.image.shape[1:]), "label_image" in ds.fields
    clf = Variant("handsnet", NET_SIZE)
    clf = clf if classifier is None else given("--classifier", classifier, "classify")
    seg = None
    if s.segmentation and labelled:
        seg = Variant("segnet", NET_SIZE, max(s.seg_widths, default=0.5))
        seg = seg if segmenter is None else given("--segmenter", segmenter, "segment")
    variants = plan_variants(s, full_hw, clf, seg)
    for v in variants:
        if v.arch == "handsnet":
            create_model("handsnet", input_size=v.size)  # ConfigError below its smallest input
    config = {"data": str(data), "classifier": classifier, "segmenter": segmenter}
    rep = Report("pareto", out, seed=s.seed, config=config | {"full_map_px": full_hw, **to_dict(s)})
    runner = Runner(data, s, Path(models_dir) if models_dir else out / "models", progress)
    rows, vgg = [], None
    for i, v in enumerate(variants):
        row, model = runner.row(v)
        rows.append(row)
        if v.arch == "vgg16" and (vgg is None or v.width > vgg[0]):
            vgg = (v.width, model)
        later = {(w.task, w.size) for w in variants[i + 1 :]}
        at_main = v.task == "classify" and v.size == clf.size
        if s.classic and at_main and (v.task, v.size) not in later:
            rows += classic_rows(runner, clf.size, vgg)  # after the last network at their size
        runner.cache = {k: t for k, t in runner.cache.items() if (k[1], k[2]) in later}
    return write_report(rep, rows, data)


SizesOpt = O.opt(
    str | None, "HandsNet inputs: <h>x<w> px or full (default 34x50,68x100,136x200,full)."
)


@experiment("pareto")
def pareto(
    dataset: O.DatasetArg,
    out: O.OutOpt,
    quick: O.QuickOpt = False,
    seed: O.SeedOpt = 0,
    classifier: O.ClassifierOpt = None,
    segmenter: O.SegmenterOpt = None,
    segmentation: O.SegmentationOpt = True,
    sizes: SizesOpt = None,
    widths: O.opt(str | None, "VGG16 widths: channel multipliers (default 0.125,0.25).") = None,
    budget_min: O.opt(float | None, "Training budget per variant (minutes; default 2).") = None,
    max_train: O.opt(int | None, "Train samples used, a seeded subset (count; 0: all).") = None,
    max_test: O.opt(int | None, "Test samples scored (count; 0: all; default 500).") = None,
    models: O.ModelsOpt = None,
    threads: O.ThreadsOpt = 2,
    progress: O.ProgressOpt = True,
) -> Path:
    """Pareto: accuracy and mean IoU against CPU time for every model, width and input size.

    CPU ms per image at batch 1 on 1 thread; the Pareto front and the paper's published points.

    --quick: HandsNet 34x50 and 68x100, VGG16 w0.125, SegNet and FCN-16s w0.25, 0.4 min per
    variant, 1000 train and 300 test samples.
    """
    O.check_segmenter(segmentation, segmenter)
    changes = {
        "sizes": O.parse_list("--sizes", sizes, str),
        "widths": O.parse_list("--widths", widths, float),
    }
    changes |= {"budget_min": budget_min, "segmentation": segmentation, "seed": seed}
    changes = {k: v for k, v in changes.items() if v is not None} | {"threads": threads}
    for key, value in (("max_train", max_train), ("max_test", max_test)):
        if value is not None:
            changes[key] = value or None  # 0 = every sample
    settings = dataclasses.replace(QUICK if quick else FULL, **changes)
    kw = {"classifier": classifier, "segmenter": segmenter, "models_dir": models}
    return Path(run_pareto(dataset, out, settings, progress=progress, **kw)["report"])
