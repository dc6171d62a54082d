"""Training, scoring and timing of the pareto experiment's variants (``experiments.pareto``).

    runner = Runner(data, settings, models_dir, progress=False)
    row, model = runner.row(variant)      # trained (or given, or reused), scored, timed
    rows = classic_rows(runner, (68, 100), (0.25, vgg_model))   # BoVW, VGG16 + SVM

Times are CPU ms per image at batch 1 on 1 thread (``learn.infer.fastpath.cpu_ms_per_image``)
for the model in eval mode and for the fast path (``fast_inference``: batch norm folded,
channels-last, bf16 weights where the CPU has bf16 kernels and the predictions agree).
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np
import torch
from tqdm.auto import tqdm

from learn.classical.bovw import BagOfVisualWords
from learn.classical.run import confusion, ms_per_image
from learn.classical.vgg_svm import VggSvmClassifier
from learn.config import BovwConfig, preset_run
from learn.data.load import materialize, open_split, subset
from learn.evaluate.scoring import scored_fast_path
from learn.infer.fastpath import cpu_ms_per_image, fast_inference
from learn.models import count_parameters
from learn.train import checkpoint as C
from learn.train.device import check_precision
from learn.train.loop import build, epoch_seed, get_batch, make_loss, train_step, views_of
from learn.train.validation import evaluate_tensors, scores
from tactile.config import to_dict

SVM_ARRAYS = ("svm_coef", "svm_intercept")  # learned arrays of a linear SVM (learn.classical)
HEAD = ("name", "arch", "task", "width", "size", "params", "training")  # first keys of a row


def model_of(checkpoint: Path):
    """The ModelConfig of a checkpoint (DataError when there is none at ``checkpoint``)."""
    return C.run_of(C.load_checkpoint(checkpoint), checkpoint).model


def variant_run(v, s):
    """The preset RunConfig of variant ``v``'s architecture at its size and width, with the
    settings' seed and threads, no validation."""
    run = preset_run(v.arch, seed=s.seed)
    model = dataclasses.replace(run.model, input_size=v.size, width=v.width or run.model.width)
    return dataclasses.replace(run, model=model, val_fraction=0.0, threads=s.threads)


def batches(run, n_items: int):
    """Item indices (B,) of every step: a seeded permutation of the ``n_items`` (sample, view)
    pairs per epoch (as ``learn.train.loop.train_epoch``), for at most the run's epochs."""
    for epoch in range(run.train.epochs):
        torch.manual_seed(epoch_seed(run.train.seed, epoch))
        order = torch.randperm(n_items)
        yield from order.split(run.train.batch_size)


def train_budgeted(run, train, budget_s: float, max_steps: float, init=None, progress=False):
    """SGD on ``train`` (TensorData) until ``budget_s`` seconds or ``max_steps`` steps have
    passed, at most the run's epochs, at a constant lr, from checkpoint ``init`` (a path) when
    given; (model in eval mode, {steps, images seen, epochs (fraction), minutes})."""
    check_precision(run.device, run.precision)
    torch.set_num_threads(run.threads)
    model, optimizer, _ = build(run, None if init is None else C.load_checkpoint(init))
    loss_fn, views = make_loss(run, train), views_of(run)
    steps, images, t0 = 0, 0, time.perf_counter()
    desc = f"{run.model.arch} {run.model.input_size}"
    bar = tqdm(total=round(budget_s), disable=not progress, leave=False, unit="s", desc=desc)
    model.train()
    for items in batches(run, len(train.y) * len(views)):
        if steps >= max_steps or time.perf_counter() - t0 >= budget_s:
            break
        x, y = get_batch(train, items, views)
        train_step(model, loss_fn, optimizer, x, y, run)
        steps, images = steps + 1, images + len(y)
        bar.update(min(round(time.perf_counter() - t0), bar.total) - bar.n)
    bar.close()
    minutes = (time.perf_counter() - t0) / 60
    info = {"steps": steps, "images": images, "epochs": images / (len(train.y) * len(views))}
    return model.eval(), info | {"minutes": minutes}


def measure(model, test, task: str, size: tuple[int, int], runs: int) -> dict:
    """Test metrics of the fast CPU path (bf16 kept only while the accuracy stays within 0.5
    points of eval mode's) and CPU ms/image of eval mode and of the fast path."""
    n_cls = model.num_classes
    ref = evaluate_tensors(model, test, n_cls).metrics["accuracy"] if task == "classify" else None
    fast, res = scored_fast_path(lambda **kw: fast_inference(model, **kw), test, n_cls, ref)
    key = "accuracy" if task == "classify" else "mean_iou"
    out = {"metrics": res.metrics, "score": res.metrics[key], "cm": res.cm.tolist()}
    out |= {"n_test": len(test.y), "bf16": bool(getattr(fast, "bf16", False))}
    ms = {
        k: cpu_ms_per_image(net, size, 1, runs)
        for k, net in (("ms_eval", model), ("ms_fast", fast))
    }
    return out | ms


class Runner:
    """Loads tensors once per (split, task, size), trains or reuses variants and scores them.

    s : the ``ParetoSettings``. mains : task -> checkpoint of the main model, the start of
    the variants at other sizes (``Variant.warm``).
    """

    def __init__(self, data: Path, s, models_dir: Path, progress: bool) -> None:
        self.data, self.s, self.models_dir, self.progress = data, s, models_dir, progress
        self.cache: dict[tuple, object] = {}
        self.mains: dict[str, Path] = {}

    def tensors(self, split: str, task: str, size: tuple[int, int]):
        """TensorData of a split at ``size`` (a seeded subset of max_train / max_test)."""
        key = (split, task, size)
        if key not in self.cache:
            ds = open_split(self.data, split, task, size, None, self.s.seed)
            cap = self.s.max_train if split == "train" else self.s.max_test
            if cap is not None and cap < len(ds.indices):
                rng = np.random.default_rng([self.s.seed, split == "test"])
                ds = subset(ds, np.sort(rng.choice(len(ds.indices), cap, replace=False)))
            self.cache[key] = materialize(ds, f"{split} {size}", self.progress)
        return self.cache[key]

    def model(self, v):
        """(model in eval mode, training description) of a variant: given, reused or trained."""
        if v.checkpoint is not None:
            ckpt = C.load_checkpoint(v.checkpoint)
            self.mains.setdefault(v.task, v.checkpoint)
            model = C.model_from_checkpoint(ckpt, where=v.checkpoint)[0]
            return model, f"given checkpoint ({ckpt['epoch']} epochs)"
        run, path = variant_run(v, self.s), self.models_dir / v.key / C.BEST
        init = self.mains.get(v.task) if v.warm else None
        budget = {"budget_min": self.s.budget_min, "max_steps": self.s.max_steps}
        budget |= {"max_train": self.s.max_train, "init": None if init is None else str(init)}
        ckpt = C.load_checkpoint(path) if path.is_file() else {}
        same = ckpt.get("budget") == budget and ckpt.get("config") == to_dict(run)
        if same and not C.inputs_stale(ckpt, run.task):
            print(f"reusing {path}")
            model, info = C.model_from_checkpoint(ckpt, where=path)[0], ckpt["training"]
        else:
            model, info = self.train(v, run, init)
            extra = {"budget": budget, "training": info, "task": run.task, "seed": run.train.seed}
            epoch = int(np.ceil(info["epochs"]))
            ckpt = C.make_checkpoint(model, to_dict(run), epoch=epoch, best_metric=np.nan, **extra)
            C.save_checkpoint(ckpt, path)
        self.mains.setdefault(v.task, path)
        start = "" if init is None else ", from the main model"
        steps = f"{info['steps']} steps, {info['epochs']:.2f} epochs"
        return model, f"{info['minutes']:.1f} min: {steps}{start}"

    def train(self, v, run, init):
        """(model, info) of ``run`` trained for the settings' budget (``train_budgeted``)."""
        train, budget_s = self.tensors("train", v.task, v.size), 60 * self.s.budget_min
        return train_budgeted(run, train, budget_s, self.s.max_steps or np.inf, init, self.progress)

    def row(self, v) -> tuple[dict, object]:
        """(result row, model) of one network variant."""
        model, training = self.model(v)
        res = measure(model, self.tensors("test", v.task, v.size), v.task, v.size, self.s.time_runs)
        row = head(v.name, v.arch, v.task, v.width, v.size, count_parameters(model), training)
        return row | res, model


def head(name, arch, task, width, size, params, training) -> dict:
    """The first entries of a result row: what the variant is and how it was trained."""
    values = (name, arch, task, width, list(size), int(params), training)
    return dict(zip(HEAD, values, strict=True))


def classic_rows(runner: Runner, size: tuple[int, int], vgg) -> list[dict]:
    """BoVW (80 words, SIFT) and, given ``vgg`` = (width, VGG16 classifier), its fc7 features
    + a linear SVM, both fitted on the train split at ``size``; times include the features."""
    train = runner.tensors("train", "classify", size)
    images, labels, seed = train.x[:, 0].numpy(), train.y.numpy(), runner.s.seed
    t0 = time.perf_counter()
    bovw = BagOfVisualWords(BovwConfig(seed=seed)).fit(images, labels)
    params = sum(bovw.to_arrays()[1][k].size for k in ("vocabulary", *SVM_ARRAYS))
    fitted = f"fitted in {(time.perf_counter() - t0) / 60:.1f} min"
    row = head("BoVW (80 words)", "bovw", "classify", None, size, params, fitted)
    rows = [classic_row(runner, row, bovw)]
    if vgg is not None:
        width, model = vgg
        t0 = time.perf_counter()
        svm = VggSvmClassifier(model, seed=seed).fit(train.x, labels)
        params = count_parameters(model) + sum(svm.to_arrays()[1][k].size for k in SVM_ARRAYS)
        fitted = f"SVM fitted in {(time.perf_counter() - t0) / 60:.1f} min on VGG16 w{width:g}"
        row = head(f"VGG16 w{width:g} + SVM", "vgg_svm", "classify", None, size, params, fitted)
        rows.append(classic_row(runner, row, svm))
    return rows


def classic_row(runner: Runner, row: dict, model) -> dict:
    """``row`` with the test scores and times of a classical classifier (``model.predict``)."""
    test = runner.tensors("test", "classify", tuple(row["size"]))
    images, truth = test.x[:, 0].numpy(), test.y.numpy()
    cm = torch.as_tensor(confusion(truth, model.predict(images), 2))
    ms = ms_per_image(model, images, 1, min(runner.s.time_runs, len(images)), rounds=1)
    res = {"metrics": scores(cm), "score": scores(cm)["accuracy"], "cm": cm.tolist()}
    return row | res | {"n_test": len(truth), "bf16": False, "ms_eval": ms, "ms_fast": ms}
