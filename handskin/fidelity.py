"""`handskin experiment fidelity`: model no more than a scene needs.

For simulation settings from cheap to rich (`handskin.fidelity_settings`), generate ``n`` samples
with one seed (sample ``i`` is the same press by the same person or object in every setting, up
to what the setting changes) and measure the generation speed; train the same short HandsNet
probe on each (optionally SegNet) and test every model on ONE test set: the test split of the
richest setting's dataset (`tactile.dataset.splits`: subjects and object instances disjoint
from its train split, class-stratified). Each setting trains on its samples whose person and
object instance are not in that test split. (Another dataset seed would give other people but
not other objects: an instance depends only on its id, `sim.primitives.instance_rng`.)

    run_fidelity("out/fidelity", quick=True)      # Python; the command calls this

Datasets live in ``--data`` (default ``OUT/data``), one folder per setting named after a hash
of its configuration, and are reused when complete (the generator resumes a partial one); the
measured speed is kept beside each folder (``<folder>.timing.json``). Models live in
``OUT/models`` and are reused when trained to the requested epochs.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from handskin import fidelity_data as FD
from handskin import fidelity_report as FR
from handskin import fidelity_settings as FS
from tactile.errors import ConfigError, require_folder

if TYPE_CHECKING:
    from torch import nn

    from learn.folder import TensorData
    from learn.train import RunConfig
    from sim.gen_config import GenerateConfig

FULL = {"n": 2000, "epochs": 20}  # ~1,400 training / ~600 test samples; ≲ 60 min on 2 cores
QUICK = {"n": 240, "epochs": 20}  # ~170 / ~70; < 10 min on 2 cores
# Network input (rows, columns) px: half the paper's 68 x 100 in each direction, so the probe
# trains ~4x faster and 20 epochs fit the budget; the same for every setting (--image-px).
IMAGE_PX = (34, 50)
LIMITS = {"n": (8, 10**6), "epochs": (1, 1000), "workers": (1, 256)}
METRIC = {"handsnet": "accuracy", "segnet": "mean_iou"}


@dataclasses.dataclass(frozen=True)
class FidelityPlan:
    """Sizes of one run: samples per setting, probe epochs, network input (rows, columns) px,
    generator processes, seed, whether SegNet is trained too, and where the probes train."""

    n: int
    epochs: int
    image_px: tuple[int, int]
    workers: int
    seed: int
    segnet: bool
    device: str = "cpu"

    def __post_init__(self) -> None:
        for name, (lo, hi) in LIMITS.items():
            value = getattr(self, name)
            if not lo <= value <= hi:
                raise ConfigError(f"{name} = {value} is out of range; allowed [{lo}, {hi}]")
        if min(self.image_px) < 24 or max(self.image_px) > 1024:
            raise ConfigError(
                f"image_px = {self.image_px}: each side must be 24..1024 pixels "
                "(HandsNet's four pooling blocks need >= 24)"
            )
        if not 0 <= self.seed < 2**63:
            raise ConfigError(f"seed = {self.seed} is out of range; allowed [0, 2**63 - 1]")
        if self.device != "cpu":
            from learn.device import check_device  # imports torch

            check_device(self.device)


def parse_image_px(text: str) -> tuple[int, int]:
    """``"34x50"`` -> (34, 50); ConfigError naming the expected form."""
    try:
        rows, cols = (int(t) for t in text.lower().split("x"))
    except ValueError as err:
        raise ConfigError(f"--image-px {text!r}: expected ROWSxCOLUMNS pixels, e.g. 34x50") from err
    return rows, cols


def probe_run(arch: str, plan: FidelityPlan) -> RunConfig:
    """The arch's `learn.config` preset (optimiser, lr, batch, loss) for ``plan.epochs`` (lr drop
    at 3/4), at ``plan.image_px``, without flips and without validation (the last epoch counts)."""
    from learn.experiments.models import preset_run

    drop = max(1, round(0.75 * plan.epochs))
    run = preset_run(
        arch, epochs=plan.epochs, seed=plan.seed, lr_drop_period_epochs=drop, device=plan.device
    )
    model = dataclasses.replace(run.model, input_size=tuple(plan.image_px))
    return dataclasses.replace(run, model=model, val_fraction=0.0, flips=False)


def read_tensors(
    folder: Path, task: str, plan: FidelityPlan, indices: np.ndarray, progress: bool
) -> TensorData:
    """Samples ``indices`` of a dataset as TensorData at ``plan.image_px`` (no flips)."""
    from learn.data import TorchTactileDataset
    from learn.folder import materialize

    ds = TorchTactileDataset(folder, split=None, task=task, size=plan.image_px, flips=False)
    ds.indices = np.asarray(indices, dtype=np.int64)
    return materialize(ds, f"reading {folder.name}", progress)


def trained_model(
    run: RunConfig, train: Callable[[], TensorData], out: Path, progress: bool
) -> nn.Module:
    """The probe trained on ``train`` (a callable giving TensorData) into ``out``, reused when
    ``last.pt`` holds the requested epochs (resumed when fewer); the model in eval mode."""
    from learn.checkpoint import LAST, load_checkpoint, model_from_checkpoint
    from learn.folder import HAND_NAMES, Data
    from learn.train import fit
    from tactile.labels import CLASS_NAMES

    last = out / LAST
    if last.is_file() and int(load_checkpoint(last)["epoch"]) >= run.train.epochs:
        print(f"reusing {last}")
    else:
        tensors = train()
        names = HAND_NAMES if run.task == "classify" else CLASS_NAMES
        desc = {"kind": "dataset", "n_train": len(tensors.y)}
        fit(run, Data(tensors, None, None, names, desc), out, resume=True, progress=progress)
    return model_from_checkpoint(load_checkpoint(last))[0]


def _tag(*parts: object) -> str:
    import hashlib

    text = json.dumps(parts, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:10]


def evaluate_setting(
    arch: str,
    folder: Path,
    test_dir: Path,
    tests: dict[str, TensorData],
    out: Path,
    plan: FidelityPlan,
    progress: bool,
) -> float:
    """Test metric (%) of the ``arch`` probe trained on ``folder`` minus the test groups:
    accuracy (HandsNet) or mean IoU (SegNet), on ``tests[arch]`` (TensorData)."""
    from learn.evaluate import evaluate_tensors
    from tactile.config import to_dict
    from tactile.dataset.manifest import read_manifest

    run = probe_run(arch, plan)
    prints = [read_manifest(f)["fingerprint"] for f in (folder, test_dir)]
    name = f"{arch}-{folder.name}-{_tag(to_dict(run), prints)}"
    indices = FD.training_indices(folder, test_dir)

    def train():
        return read_tensors(folder, run.task, plan, indices, progress)

    model = trained_model(run, train, out / "models" / name, progress)
    res = evaluate_tensors(model, tests[arch], run.model.num_classes, run.eval_batch_size)
    return 100.0 * float(res.metrics[METRIC[arch]])


def run_fidelity(
    out: str | Path,
    *,
    data_dir: str | Path | None = None,
    settings: str | list[str] | None = None,
    quick: bool = False,
    seed: int = 0,
    n: int | None = None,
    epochs: int | None = None,
    image_px: tuple[int, int] | None = None,
    workers: int | None = None,
    part: str = "forearm",
    segnet: bool = False,
    base: GenerateConfig | None = None,
    device: str = "cpu",
    progress: bool = True,
) -> dict:
    """Run the experiment into ``out`` (report.md, results.json, PNG charts); returns results.

    n : samples generated per setting (None: `QUICK` or `FULL`). base : the GenerateConfig the
    settings change (default: defaults on ``part``). device : where the probes train ("cpu",
    "cuda", "cuda:N"). Every input is checked before any work.
    """
    from sim.gen_config import GenerateConfig
    from sim.generate import default_workers

    sizes = QUICK if quick else FULL
    plan = FidelityPlan(
        sizes["n"] if n is None else n,
        sizes["epochs"] if epochs is None else epochs,
        tuple(IMAGE_PX if image_px is None else image_px),
        default_workers() if workers is None else workers,
        seed,
        segnet,
        device,
    )
    chosen = FS.resolve_settings(settings, quick)
    base = base if base is not None else GenerateConfig(part=part)
    configs = {
        s.name: FS.setting_config(s, base, n=plan.n, seed=seed)
        for s in (*chosen, FS.BY_NAME[FS.RICHEST])
    }
    out = Path(out)
    data = Path(data_dir) if data_dir is not None else out / "data"
    for path, what in ((out, "--out"), (data, "--data")):
        require_folder(path, what)
    return _run(out, data, plan, chosen, configs, quick, progress)


def _run(
    out: Path, data: Path, plan: FidelityPlan, chosen, configs: dict, quick: bool, progress: bool
) -> dict:
    from learn.experiments.report import Report

    rich = configs[FS.RICHEST]
    report = Report(
        "fidelity",
        out,
        seed=plan.seed,
        config={
            **dataclasses.asdict(plan),
            "quick": quick,
            "settings": [s.name for s in chosen],
            "part": rich.part,
            "data": str(data),
        },
    )
    data.mkdir(parents=True, exist_ok=True)
    folders = {k: data / f"{k}-{FS.config_tag(c)}" for k, c in configs.items()}
    print(f"[fidelity] {FS.RICHEST}: {plan.n} samples (its test split is the shared test set)")
    timings = {FS.RICHEST: FD.generate_set(rich, folders[FS.RICHEST], plan.workers, progress)}
    test_dir = folders[FS.RICHEST]
    archs = ("handsnet", "segnet") if plan.segnet else ("handsnet",)
    with_test = FD.test_indices(test_dir)
    tests = {
        a: read_tensors(test_dir, probe_run(a, plan).task, plan, with_test, progress) for a in archs
    }
    rows = []
    for setting in chosen:
        cfg, folder = configs[setting.name], folders[setting.name]
        if setting.name not in timings:
            print(f"[fidelity] {setting.name}: {plan.n} samples ({setting.note})")
            timings[setting.name] = FD.generate_set(cfg, folder, plan.workers, progress)
        scores = {
            a: evaluate_setting(a, folder, test_dir, tests, out, plan, progress) for a in archs
        }
        rows.append(
            {
                "name": setting.name,
                "note": setting.note,
                "knobs": FS.knob_values(cfg),
                "changes": dict(setting.changes),
                "dataset": str(folder),
                "n_train": len(FD.training_indices(folder, test_dir)),
                **timings[setting.name],
                "accuracy_pct": scores["handsnet"],
                "miou_pct": scores.get("segnet"),
            }
        )
    test = {"dataset": str(test_dir), "n_test": len(with_test), **timings[FS.RICHEST]}
    return FR.write_report(report, rows, plan, rich, test)


def register(app) -> None:
    """Add `handskin experiment fidelity`."""
    from handskin.fidelity_cli import fidelity_command
    from learn.cli import _needs_torch

    app.command("fidelity")(_needs_torch(fidelity_command))
