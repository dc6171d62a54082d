"""Training and scoring of the pareto experiment's variants (``learn.experiments.pareto``).

    runner = Runner(data, settings, models_dir, progress=False)
    row, model = runner.row(variant)      # trained (or given / reused), scored, timed
    rows = classic_rows(runner, (68, 100), ("0.25", vgg_model))   # BoVW, VGG16 + SVM

Times are CPU ms per image at batch 1 on 1 thread (``learn.fastpath.cpu_ms_per_image``: median
of the runs after 20 warm-up runs, network forward only, random input) for the model in eval
mode and for the fast path (``fast_inference``: batch norm folded, channels-last, bf16 weights
where the CPU has bf16 kernels and the predictions agree).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from learn.experiments.pareto import ParetoSettings, Variant, variant_run

SVM_ARRAYS = ("svm_coef", "svm_intercept")  # learned arrays of a linear SVM (learn.classical)


def batches(run, n_items: int):
    """Item indices (B,) of every step: a seeded permutation of the ``n_items`` (sample, view)
    pairs per epoch (as ``learn.train.train_epoch``), for at most ``run.train.epochs`` epochs."""
    import torch

    from learn.train import epoch_seed

    for epoch in range(run.train.epochs):
        torch.manual_seed(epoch_seed(run.train.seed, epoch))
        order = torch.randperm(n_items)
        for start in range(0, n_items, run.train.batch_size):
            yield order[start : start + run.train.batch_size]


def train_budgeted(
    run, train, budget_s: float, max_steps: float, init_from=None, progress: bool = False
):
    """SGD on ``train`` (TensorData) until ``budget_s`` seconds or ``max_steps`` steps have
    passed, at most ``run.train.epochs`` epochs, constant lr; (model in eval mode, info dict:
    steps, images seen, epochs (fraction), minutes)."""
    import torch
    from tqdm.auto import tqdm

    from learn.train import build, check_precision, get_batch, make_loss, train_step, views_of

    check_precision(run)
    torch.set_num_threads(run.threads)
    model, optimizer, _, _ = build(run, init_from)
    loss_fn, views = make_loss(run, train), views_of(run)
    steps, images, t0 = 0, 0, time.perf_counter()
    bar = tqdm(
        total=round(budget_s),
        disable=not progress,
        leave=False,
        unit="s",
        desc=f"{run.model.arch} {run.model.input_size}",
    )
    model.train()
    for items in batches(run, len(train.y) * len(views)):
        if steps >= max_steps or time.perf_counter() - t0 >= budget_s:
            break
        x, y = get_batch(train, items, views)
        train_step(model, loss_fn, optimizer, x, y, run.task, run.precision)
        steps, images = steps + 1, images + len(y)
        bar.update(min(round(time.perf_counter() - t0), bar.total) - bar.n)
    bar.close()
    info = {
        "steps": steps,
        "images": images,
        "epochs": images / (len(train.y) * len(views)),
        "minutes": (time.perf_counter() - t0) / 60,
    }
    return model.eval(), info


class Runner:
    """Loads tensors once per (split, task, size), trains or reuses variants and scores them."""

    def __init__(self, data: Path, s: ParetoSettings, models_dir: Path, progress: bool) -> None:
        self.data, self.s, self.models_dir, self.progress = data, s, models_dir, progress
        self.cache: dict[tuple, object] = {}
        self.resize: dict[tuple[int, int], float] = {}  # size -> resize ms/image
        self.mains: dict[str, Path] = {}  # task -> checkpoint of the main model

    def tensors(self, split: str, task: str, size: tuple[int, int]):
        """TensorData of a split at ``size`` (seeded subset of max_train / max_test samples)."""
        key = (split, task, size)
        if key not in self.cache:
            from learn.folder import materialize, open_split, subset

            ds = open_split(self.data, split, task, size, None, self.s.seed)
            cap = self.s.max_train if split == "train" else self.s.max_test
            if cap is not None and cap < len(ds.indices):
                rng = np.random.default_rng([self.s.seed, split == "test"])
                ds = subset(ds, np.sort(rng.choice(len(ds.indices), cap, replace=False)))
            self.cache[key] = materialize(ds, f"{split} {size}", self.progress)
        return self.cache[key]

    def model(self, v: Variant):
        """(model in eval mode, training description) of a variant: given, reused or trained."""
        from learn.checkpoint import load_checkpoint, model_from_checkpoint

        if v.checkpoint is not None:
            ckpt = load_checkpoint(v.checkpoint)
            self.mains.setdefault(v.task, v.checkpoint)
            return model_from_checkpoint(ckpt)[0], f"given checkpoint ({ckpt['epoch']} epochs)"
        run, path = variant_run(v, self.s), self.models_dir / v.key / "best.pt"
        init = self.mains.get(v.task) if v.warm and self.s.warm_start else None
        budget = {
            "budget_min": self.s.budget_min,
            "max_steps": self.s.max_steps,
            "max_train": self.s.max_train,
            "init": None if init is None else str(init),
        }
        model, info = self._reuse(path, run, budget) or self._train(v, run, path, budget, init)
        self.mains.setdefault(v.task, path)
        start = "" if init is None else ", from the main model"
        return model, (
            f"{info['minutes']:.1f} min: {info['steps']} steps, {info['epochs']:.2f} epochs{start}"
        )

    def _reuse(self, path: Path, run, budget: dict):
        from learn.checkpoint import inputs_stale, load_checkpoint, model_from_checkpoint
        from tactile.config import to_dict

        if not path.is_file():
            return None
        ckpt = load_checkpoint(path)
        if ckpt.get("budget") != budget or ckpt["config"] != to_dict(run):
            return None
        if inputs_stale(ckpt, run.task):
            print(
                f"retraining {path}: a segmenter trained before its inputs kept their labels' "
                "support (learn.inputs)"
            )
            return None
        print(f"reusing {path}")
        return model_from_checkpoint(ckpt)[0], ckpt["training"]

    def _train(self, v: Variant, run, path: Path, budget: dict, init):
        from learn.checkpoint import make_checkpoint, save_checkpoint
        from tactile.config import to_dict

        max_steps = self.s.max_steps or float("inf")
        model, info = train_budgeted(
            run,
            self.tensors("train", v.task, v.size),
            60 * self.s.budget_min,
            max_steps,
            init,
            self.progress,
        )
        ckpt = make_checkpoint(
            model,
            to_dict(run),
            epoch=int(np.ceil(info["epochs"])),
            best_metric=float("nan"),
            budget=budget,
            training=info,
            task=run.task,
            seed=run.train.seed,
        )
        save_checkpoint(ckpt, path)
        return model, info

    def resize_ms(self, size: tuple[int, int]) -> float:
        """:func:`resize_ms` of ``size``, measured once per size."""
        if size not in self.resize:
            self.resize[size] = resize_ms(self.data, size)
        return self.resize[size]

    def row(self, v: Variant) -> tuple[dict, object]:
        """(result row, model) of one network variant."""
        from learn.models import count_parameters

        model, training = self.model(v)
        res = measure(model, self.tensors("test", v.task, v.size), v.task, v.size, self.s.time_runs)
        row = {
            "name": v.name,
            "arch": v.arch,
            "task": v.task,
            "width": v.width,
            "size": list(v.size),
            "params": count_parameters(model),
            "training": training,
            "resize_ms": self.resize_ms(v.size),
            **res,
        }
        return row, model


def measure(model, test, task: str, size: tuple[int, int], runs: int) -> dict:
    """Test metrics of the fast CPU path (``fast_inference``; bf16 kept only if the accuracy
    stays within 0.5 points of eval mode) and CPU ms/image of eval mode and the fast path."""
    from learn.evaluate import evaluate_tensors, scored_fast_path
    from learn.fastpath import cpu_ms_per_image, fast_inference

    n_cls = model.num_classes
    ref = evaluate_tensors(model, test, n_cls).metrics["accuracy"] if task == "classify" else None
    fast, res = scored_fast_path(lambda **kw: fast_inference(model, **kw), test, n_cls, ref)
    key = "accuracy" if task == "classify" else "mean_iou"
    return {
        "metrics": res.metrics,
        "score": res.metrics[key],
        "cm": res.cm.tolist(),
        "n_test": len(test.y),
        "bf16": bool(getattr(fast, "bf16", False)),
        "ms_eval": cpu_ms_per_image(model, size, 1, runs),
        "ms_fast": cpu_ms_per_image(fast, size, 1, runs),
    }


def resize_ms(data: Path, size: tuple[int, int], runs: int = 20) -> float:
    """Median ms to resize one stored test image to ``size`` (0 when it is the stored size)."""
    from tactile.dataset.reader import DatasetReader
    from tactile.resize import resize_image

    with DatasetReader(data) as ds:
        image = ds.image[int(ds.splits["test"][0])]
    if tuple(image.shape) == tuple(size):
        return 0.0
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        resize_image(image, size)
        times.append(time.perf_counter() - t0)
    return 1e3 * float(np.median(times))


def median_ms(call: Callable[[int], object], n: int) -> float:
    """Median wall time of ``call(i)`` for i < n, in ms, with 1 torch thread."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        times = []
        for i in range(n):
            t0 = time.perf_counter()
            call(i)
            times.append(time.perf_counter() - t0)
    finally:
        torch.set_num_threads(before)
    return 1e3 * float(np.median(times))


def classic_row(
    name: str,
    arch: str,
    predict: Callable,
    test,
    size: tuple[int, int],
    params: int,
    runner: Runner,
    training: str,
) -> dict:
    """Result row of a non-network-only classifier: ``predict(x (B, 1, h, w)) -> (B,) labels``."""
    import torch

    from learn import metrics as M
    from learn.evaluate import scores

    cm = M.confusion_matrix(test.y, torch.as_tensor(np.asarray(predict(test.x))), 2)
    ms = median_ms(lambda i: predict(test.x[i : i + 1]), min(runner.s.time_runs, len(test.y)))
    return {
        "name": name,
        "arch": arch,
        "task": "classify",
        "width": None,
        "size": list(size),
        "params": int(params),
        "training": training,
        "metrics": scores(cm),
        "score": scores(cm)["accuracy"],
        "cm": cm.tolist(),
        "n_test": len(test.y),
        "bf16": False,
        "ms_eval": ms,
        "ms_fast": ms,
        "resize_ms": runner.resize_ms(size),
    }


def classic_rows(
    runner: Runner, size: tuple[int, int], vgg: tuple[float, object] | None
) -> list[dict]:
    """BoVW (80 words, SIFT) and, given ``(width, VGG16 classifier)``, its fc7 features + linear
    SVM (C = 0.25), both fitted on the train split at ``size``; the times include feature
    extraction."""
    from learn.bovw import BagOfVisualWords
    from learn.config import BovwConfig
    from learn.models import count_parameters
    from learn.vgg_svm import VggSvmClassifier

    train = runner.tensors("train", "classify", size)
    test = runner.tensors("test", "classify", size)
    t0 = time.perf_counter()
    bovw = BagOfVisualWords(BovwConfig(seed=runner.s.seed)).fit(
        train.x[:, 0].numpy(), train.y.numpy()
    )
    params = sum(bovw.to_arrays()[1][k].size for k in ("vocabulary", *SVM_ARRAYS))
    fitted = f"fitted in {(time.perf_counter() - t0) / 60:.1f} min"
    rows = [
        classic_row(
            "BoVW (80 words)",
            "bovw",
            lambda x: bovw.predict(x[:, 0].numpy()),
            test,
            size,
            params,
            runner,
            fitted,
        )
    ]
    if vgg is not None:
        width, model = vgg
        t0 = time.perf_counter()
        svm = VggSvmClassifier(model, seed=runner.s.seed).fit(train.x, train.y.numpy())
        params = count_parameters(model) + sum(svm.to_arrays()[1][k].size for k in SVM_ARRAYS)
        fitted = f"SVM fitted in {(time.perf_counter() - t0) / 60:.1f} min on VGG16 w{width:g}"
        rows.append(
            classic_row(
                f"VGG16 w{width:g} + SVM",
                "vgg_svm",
                svm.predict,
                test,
                size,
                params,
                runner,
                fitted,
            )
        )
    return rows
