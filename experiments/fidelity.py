"""`handskin experiment fidelity`: simulate no more than a scene needs.

For simulation settings from cheap to rich (``experiments.fidelity_settings``), generate ``n``
samples with one seed (sample ``i`` is the same press by the same person or object in every
setting, up to what the setting changes) and measure the generation speed; train the same short
HandsNet probe on each (and SegNet with ``--segmentation``) and test every model on ONE test
set: the test split of the richest setting's dataset (subjects and object instances disjoint
from its train split). Each setting trains on its samples whose person and object instance are
not in that test split (object instances depend on their id alone, so all settings share them).

    run_fidelity("out/fidelity", QUICK, quick=True)    # 240 samples, the quick settings

Datasets live in ``--datasets`` (default ``OUT/data``), one folder per setting named after a
hash of its configuration, reused when complete (the generator resumes a partial one); the
measured speed is kept beside each (``<folder>.timing.json``). Probes live in ``OUT/models``.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np

from experiments import experiment
from experiments import fidelity_settings as FS
from experiments import options as O
from experiments.fidelity_prints import print_statistics
from experiments.fidelity_report import write_report
from experiments.report import Report
from learn.config import preset_run
from sim.skin import DEFAULT_PART
from tactile.dataset.manifest import jsonable, read_manifest
from tactile.dataset.reader import open_dataset
from tactile.errors import ConfigError, DataError

METRIC = {"handsnet": "accuracy_pct", "segnet": "miou_pct"}


@dataclasses.dataclass(frozen=True)
class FidelityPlan:
    """Sizes of one run: samples per setting, probe epochs, probe input (rows, columns) px,
    generator processes (None: all cores), seed, whether SegNet is trained too, where the
    probes train."""

    n: int = 2000  # samples per setting (a 70 / 30 % split of the richest gives the test set)
    epochs: int = 20
    image_px: tuple[int, int] = (34, 50)  # half the paper's 68 x 100 each way: 1/4 of the pixels
    workers: int | None = None
    seed: int = 0
    segmentation: bool = False
    device: str = "cpu"

    def __post_init__(self) -> None:
        for flag, value, least in (("--n", self.n, 8), ("--epochs", self.epochs, 1)):
            O.check_at_least(flag, value, least)
        O.check_at_least("--workers", self.workers)
        O.check_at_least("--seed", self.seed, 0)
        if min(self.image_px) < 24:
            raise ConfigError(f"image_px {self.image_px}: HandsNet needs >= 24 px a side")


QUICK = FidelityPlan(n=240)


def probe_run(arch: str, plan: FidelityPlan):
    """The arch's preset (``learn.config``) for ``plan.epochs`` (lr drop at 3/4), at
    ``plan.image_px``, without flips and without validation (the last epoch counts)."""
    drop = max(1, round(0.75 * plan.epochs))
    run = preset_run(arch, epochs=plan.epochs, seed=plan.seed, lr_drop_period_epochs=drop)
    model = dataclasses.replace(run.model, input_size=tuple(plan.image_px))
    return dataclasses.replace(run, model=model, val_fraction=0.0, flips=False, device=plan.device)


def generate_set(cfg, folder: Path, workers: int | None, progress: bool) -> dict:
    """Generate (or reuse) the dataset of ``cfg`` in ``folder``; its timing: samples_per_s
    (over the wall time), per_core (samples per CPU-second of this process and its workers,
    which other jobs on a shared machine change little), cpu_s, wall_s, workers, n_computed.
    A complete dataset without a recorded timing is reused with speeds None (unknown)."""
    # start-up time: sim loads MuJoCo
    from sim.generate.config import generator_version
    from sim.generate.executors import default_workers
    from sim.generate.run import generate
    from sim.warp.run import generate as generate_on_warp

    timing_path = folder.parent / f"{folder.name}.timing.json"
    if (folder / "dataset.h5").is_file():
        old = read_manifest(folder)
        if [old.get("config"), old.get("generator_version")] != [
            jsonable(cfg),
            generator_version(),
        ]:
            raise DataError(
                f"{folder} holds another configuration, or was made by other simulator code. "
                "Fix: delete it or give another --datasets folder"
            )
        print(f"reusing {folder}")
        if timing_path.is_file():
            return json.loads(timing_path.read_text())
        unknown = ("samples_per_s", "per_core", "cpu_s", "wall_s", "workers")
        return dict.fromkeys(unknown) | {"n_computed": 0}
    cpu, workers = cpu_seconds(), workers or default_workers()
    run = generate_on_warp if cfg.backend == "warp" else generate
    rep = run(cfg, folder, workers=workers, progress=progress)
    cpu, done = cpu_seconds() - cpu, rep.n_computed
    timing = {"samples_per_s": rep.samples_per_s if done else None, "cpu_s": cpu}
    timing |= {"per_core": done / cpu if done and cpu > 0 else None, "wall_s": rep.wall_s}
    timing |= {"workers": max(1, min(workers, cfg.n_chunks)), "n_computed": done}
    timing_path.write_text(json.dumps(timing, indent=1))
    return timing


UNMEASURED = ("n_train", "workers", "samples_per_s", "per_core", "cpu_s", "wall_s")
UNMEASURED += ("n_computed", "accuracy_pct", "miou_pct", "prints")


def failure_text(err: Exception) -> str:
    """What a failed setting's generation said, without the fix aimed at a user's own run."""
    return str(err).split(". Fix:")[0]


def cpu_seconds() -> float:
    """User + system CPU time (s) of this process and of its finished, reaped children (the
    generator joins its worker pool before returning)."""
    import resource  # start-up time: only generation needs it

    usage = [resource.getrusage(who) for who in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN)]
    return sum(u.ru_utime + u.ru_stime for u in usage)


def training_indices(folder: Path, test_dir: Path) -> np.ndarray:
    """(K,) int64 samples of ``folder`` whose subject and instance are in no sample of the test
    split of ``test_dir`` (both made with one seed: the same people, the same instances)."""
    with open_dataset(test_dir) as ds:
        test = ds.splits["test"]
        held_s, held_i = ds.subject_id[:][test], ds.instance_id[:][test]
    with open_dataset(folder) as ds:
        mine_s, mine_i = ds.subject_id[:], ds.instance_id[:]
    keep = ~np.isin(mine_s, held_s[held_s >= 0]) & ~np.isin(mine_i, held_i[held_i >= 0])
    return np.flatnonzero(keep).astype(np.int64)


def read_tensors(folder: Path, task: str, plan: FidelityPlan, indices, progress: bool):
    """Samples ``indices`` of a dataset as TensorData at ``plan.image_px`` (no flips)."""
    # optional: torch (the learn extra)
    from learn.data.dataset import TorchTactileDataset
    from learn.data.load import materialize

    ds = TorchTactileDataset(folder, split=None, task=task, size=plan.image_px, flips=False)
    ds.indices = np.asarray(indices, dtype=np.int64)
    return materialize(ds, f"reading {folder.name}", progress)


def score_setting(arch: str, folder: Path, test_dir: Path, test, out: Path, plan, progress):
    """Test metric (%) of the ``arch`` probe trained on ``folder`` minus the test groups:
    accuracy (HandsNet) or mean IoU (SegNet) on ``test`` (TensorData); the probe is kept in
    ``out/models`` and reused by a rerun."""
    # optional: torch (the learn extra)
    from learn.data.folder import HAND_NAMES
    from learn.data.load import Data
    from learn.train.checkpoint import load_checkpoint, model_from_checkpoint
    from learn.train.runs import train_once
    from learn.train.validation import evaluate_tensors
    from tactile.config import to_dict
    from tactile.images.labels import CLASS_NAMES

    run = probe_run(arch, plan)
    prints = [read_manifest(f)["fingerprint"] for f in (folder, test_dir)]
    tag = FS.config_tag([to_dict(run), prints])

    def make_data():
        tensors = read_tensors(folder, run.task, plan, training_indices(folder, test_dir), progress)
        names = HAND_NAMES if run.task == "classify" else CLASS_NAMES
        return Data(tensors, None, None, names, {"kind": "dataset", "n_train": len(tensors.y)})

    folder_out = out / "models" / f"{arch}-{folder.name}-{tag}"
    best, _ = train_once(folder_out, run, make_data, progress=progress)
    model = model_from_checkpoint(load_checkpoint(best), where=best)[0]
    res = evaluate_tensors(model, test, run.model.num_classes, run.eval_batch_size)
    return 100.0 * float(res.metrics["accuracy" if arch == "handsnet" else "mean_iou"])


def run_fidelity(
    out,
    plan: FidelityPlan = FidelityPlan(),
    *,
    settings=None,
    quick=False,
    part=DEFAULT_PART,
    base=None,
    datasets=None,
    progress=True,
) -> dict:
    """Run the experiment into ``out`` (report.md, results.json, PNG charts); returns results.

    settings : names or comma-separated text (None: all, or the quick ones with ``quick``).
    base : the GenerateConfig the settings change (default: the defaults on ``part``).
    datasets : the folder of the generated datasets (default ``out/data``). Every input is
    checked before any work.
    """
    # start-up time: sim loads MuJoCo
    from sim.episode.runner import SampleFailed
    from sim.generate.config import GenerateConfig, check_part

    if plan.device != "cpu":
        from learn.train.device import check_device  # optional: torch (the learn extra)

        check_device(plan.device)
    chosen = FS.resolve_settings(settings, quick)
    if any(dict(s.changes).get("backend") == "warp" for s in chosen):
        _check_warp()
    if base is None:
        check_part(part)
        base = GenerateConfig(part=part)
    every = (*chosen, FS.BY_NAME[FS.RICHEST])
    configs = {s.name: FS.setting_config(s, base, n=plan.n, seed=plan.seed) for s in every}
    out = Path(out)
    data = Path(datasets) if datasets is not None else out / "data"
    O.check_out(out, ("--datasets", data))
    config = dataclasses.asdict(plan) | {"settings": [s.name for s in chosen], "part": base.part}
    rep = Report("fidelity", out, seed=plan.seed, config=config | {"datasets": str(data)})
    folders = {k: data / f"{k}-{FS.config_tag(c)}" for k, c in configs.items()}
    print(f"[fidelity] {FS.RICHEST}: {plan.n} samples (its test split is the shared test set)")
    test_dir = folders[FS.RICHEST]
    timings = {FS.RICHEST: generate_set(configs[FS.RICHEST], test_dir, plan.workers, progress)}
    with open_dataset(test_dir) as ds:
        test_ids = np.asarray(ds.splits["test"], dtype=np.int64)
    archs = ("handsnet", "segnet") if plan.segmentation else ("handsnet",)
    tests = {
        a: read_tensors(test_dir, probe_run(a, plan).task, plan, test_ids, progress) for a in archs
    }
    rows = []
    for setting in chosen:
        cfg, folder = configs[setting.name], folders[setting.name]
        row = {"name": setting.name, "note": setting.note, "knobs": FS.knob_values(cfg)}
        row |= {"changes": dict(setting.changes), "dataset": str(folder)}
        if setting.name not in timings:
            print(f"[fidelity] {setting.name}: {plan.n} samples ({setting.note})")
            try:
                timings[setting.name] = generate_set(cfg, folder, plan.workers, progress)
            except SampleFailed as err:  # the setting cannot make these presses: a result
                print(f"[fidelity] {setting.name} fails: {err}")
                rows.append(row | dict.fromkeys(UNMEASURED) | {"failed": failure_text(err)})
                continue
        row["n_train"] = len(training_indices(folder, test_dir))
        row |= timings[setting.name] | {"miou_pct": None, "prints": print_statistics(folder)}
        for a in archs:
            row[METRIC[a]] = score_setting(a, folder, test_dir, tests[a], out, plan, progress)
        rows.append(row)
    test = {"dataset": str(test_dir), "n_test": len(test_ids), **timings[FS.RICHEST]}
    return write_report(rep, rows, plan, probe_run("handsnet", plan).train, base.part, test)


def _check_warp() -> None:
    """ConfigError before any work when the warp setting cannot run here."""
    from sim.warp.options import WarpOptions, check_warp  # start-up time: sim loads MuJoCo

    try:
        check_warp(WarpOptions())
    except ConfigError as err:
        raise ConfigError(f"setting warp: {err}; or leave warp out of --settings") from err


SettingsOpt = O.opt(str | None, f"Settings to run, comma-separated, of {', '.join(FS.BY_NAME)}.")
# as sim.skin.parts
PARTS = (
    "forearm_paper, forearm, forearm_8mm, forearm_x2, forearm_x3, forearm_x4, end_effector, plate"
)
PartOpt = O.opt(str, f"Skin part: {PARTS}, or a link mesh (.stl/.obj, m).")


@experiment("fidelity")
def fidelity(
    out: O.OutOpt,
    datasets: O.DatasetsOpt = None,
    quick: O.QuickOpt = False,
    seed: O.SeedOpt = 0,
    settings: SettingsOpt = None,
    n: O.opt(int | None, "Samples per setting (count; default 2000, --quick 240).", "--n") = None,
    epochs: O.opt(int, "Training epochs of each probe (count).") = 20,
    part: PartOpt = DEFAULT_PART,
    segmentation: O.SegmentationOpt = False,
    workers: O.opt(int | None, "Generator processes (count; default: all cores).") = None,
    device: O.DeviceOpt = "cpu",
    progress: O.ProgressOpt = True,
) -> Path:
    """Fidelity: simulation settings cheap to rich, their speed against accuracy.

    Generation speed (samples per CPU-second) of each setting against the accuracy (%) of a
    HandsNet trained on its data and tested on the richest setting's test split.

    --quick: 240 samples per setting; settings cheapest, short, no_spread, default, rich.
    """
    n = n if n is not None else (QUICK if quick else FidelityPlan()).n
    plan = {"workers": workers, "seed": seed, "segmentation": segmentation, "device": device}
    kw = {"settings": settings, "quick": quick, "part": part, "datasets": datasets}
    run_fidelity(out, FidelityPlan(n, epochs, **plan), progress=progress, **kw)
    return Path(out) / "report.md"
