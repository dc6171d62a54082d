"""A trained network (or several as one) scored on a test split: metrics on eval mode and on the
fast inference path, and CPU milliseconds per image — one row of ``handskin evaluate``'s report.

    row = evaluate_checkpoint("runs/handsnet/best.pt", "out/forearm")
    rows = [evaluate_job(job, "out/forearm") for job in eval_jobs(paths, tta=True)]
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from torch import nn

from learn.config import RunConfig
from learn.data.load import TensorData, is_dataset, materialize, open_split
from learn.evaluate.actions import evaluate_action
from learn.evaluate.contacts import contact_scores, split_contacts
from learn.infer.ensemble import FlipTTA, MeanSoftmax, Member, load_members, tta_views
from learn.infer.fastpath import check_timing, fast_inference, gpu_ms_per_image, interleaved_cpu_ms
from learn.infer.int8_file import int8_with_note
from learn.models import prepare_for_inference
from learn.train.checkpoint import is_int8, load_checkpoint, model_from_checkpoint, run_of
from learn.train.validation import EvalResult, evaluate_tensors, scores
from tactile.dataset.reader import DATASET
from tactile.errors import ConfigError

SEG_KEYS = ("pixel_accuracy", "mean_accuracy", "mean_iou", "fw_iou")


@dataclass(frozen=True)
class Job:
    """One row of the report: a checkpoint (or an ensemble's list of them), with test-time flips
    or not, as int8 or not."""

    paths: tuple[Path, ...]
    tta: bool = False
    int8: bool = False


def eval_jobs(
    checkpoints: list[Path], tta: bool = False, ensemble: bool = False, int8: bool = False
) -> list[Job]:
    """The report's rows in order: every ``.pt`` checkpoint, then with test-time flips
    (``tta``), each task's ensemble (``ensemble``) and each float HandsNet as int8 (``int8``).
    Every file is loaded and checked here, before any scoring; ConfigError naming the fix for a
    file given twice, a network trained without flips under ``tta``, or nothing to ensemble or
    quantize."""
    if len({c.resolve() for c in checkpoints}) < len(checkpoints):
        raise ConfigError("a checkpoint is given twice. Fix: give each .pt file once")
    ckpts = {c: load_checkpoint(c) for c in checkpoints}
    by_task: dict[str, list[Path]] = {}
    jobs = []
    for c, ckpt in ckpts.items():
        run = run_of(ckpt, c)
        if run.task == "both" and (tta or ensemble):
            raise ConfigError(
                f"{c} is a class-and-parts network; --tta and --ensemble are for classifiers and "
                "segmenters. Fix: evaluate it without them"
            )
        if run.task == "action" and (tta or ensemble):
            raise ConfigError(
                f"{c} is an action network; --tta and --ensemble are for the image networks. "
                "Fix: evaluate it without them (or in a command of its own)"
            )
        if tta:  # a network trained without flips fails here, before any work
            tta_views(run, c)
        by_task.setdefault(run.task, []).append(c)
        jobs += [Job((c,))] + ([Job((c,), tta=True)] if tta else [])
    if ensemble:
        groups = [tuple(p) for p in by_task.values() if len(p) >= 2]
        if not groups:
            counts = ", ".join(f"{len(p)} {t}" for t, p in by_task.items()) or "no networks"
            raise ConfigError(
                f"--ensemble averages two or more networks of one task; got {counts}. Fix: give "
                "two or more classifier or segmenter .pt files"
            )
        for group in groups:
            load_members(group)  # checked alike (task, classes, input size), before any work
            jobs += [Job(group)] + ([Job(group, tta=True)] if tta else [])
    if int8:
        nets = [
            c for c, k in ckpts.items() if run_of(k).model.arch == "handsnet" and not is_int8(k)
        ]
        if not nets:
            raise ConfigError(
                "--int8 scores a float HandsNet as an int8 network; no float HandsNet checkpoint "
                "was given (int8 files of handskin quantize are scored as int8 without it). Fix: "
                "add a HandsNet .pt"
            )
        jobs += [Job((c,), int8=True) for c in nets]
    return jobs


def evaluate_checkpoint(ckpt_path: str | Path, data_path: str | Path, **kw: object) -> dict:
    """The report row of one checkpoint (`evaluate_job`'s keywords)."""
    return evaluate_job(Job((Path(ckpt_path),)), data_path, **kw)


def evaluate_job(
    job: Job,
    data_path: str | Path,
    *,
    hand_classes: tuple[str, ...] | None = None,
    threads: int = 1,
    time_runs: int = 100,
    time_rounds: int = 3,
    progress: bool = True,
) -> dict:
    """Test-split metrics (eval mode and fast path) and CPU ms/image at batch 1 of a job's
    network: ``job.tta`` with test-time flips over the views each network was trained on;
    several paths: the mean softmax of those networks; ``job.int8`` (HandsNet): its int8 copy,
    calibrated on training images of ``data_path`` (an int8 file runs as its saved network).
    Timing: each inference path's median of ``time_runs`` runs, the least over ``time_rounds``
    rounds in which the paths take turns (`learn.infer.fastpath.interleaved_cpu_ms`). On a
    dataset of several contacts per sample, eval mode's scores by number of contacts too
    (`learn.evaluate.contacts`). ``progress``: a bar while sequences are read."""
    check_timing(time_runs, time_rounds, threads)
    if len(job.paths) == 1:
        ckpt = load_checkpoint(job.paths[0])
        model, run = model_from_checkpoint(ckpt, int8_ok=True, where=job.paths[0])
        if run.task == "action":  # sequences in, its own row (learn.evaluate.actions)
            timing = {"threads": threads, "time_runs": time_runs, "time_rounds": time_rounds}
            return evaluate_action(
                job.paths[0], ckpt, model, run, Path(data_path), **timing, progress=progress
            )
        members = [Member(job.paths[0], ckpt, model, run)]
    else:
        members = load_members(job.paths)
    first, run = members[0], members[0].run
    views = [tta_views(m.run, m.path) for m in members] if job.tta else None

    def build(path_of: Callable[[nn.Module], nn.Module]) -> nn.Module:
        """One inference path of every member, flipped and averaged as the job asks."""
        nets = [path_of(m.model) for m in members]
        nets = [FlipTTA(n, v) for n, v in zip(nets, views, strict=True)] if job.tta else nets
        return nets[0] if len(nets) == 1 else MeanSoftmax(nets)

    hand = hand_classes or (first.ckpt.get("data") or {}).get("hand_classes")
    test = read_test_split(Path(data_path), run, hand, progress)
    n_cls, size = run.model.num_classes, run.model.input_size
    canvas = run.model.canvas_mm
    both = run.task == "both"  # class and parts: no scores by contacts (their rows are split)
    contacts = None if both else split_contacts(Path(data_path), run.task, size, canvas)
    keep = contacts is not None  # eval mode's predictions, scored by number of contacts
    int8 = job.int8 or is_int8(first.ckpt)
    int8_note = None
    if int8:  # one path: the int8 network is its own fast path
        q8, int8_note = int8_with_note(first.model, run, first.ckpt, Path(data_path), hand)
        ref = res = evaluate_tensors(q8, test, n_cls, keep_predictions=keep)
        fast = q8
        (t,) = interleaved_cpu_ms([q8], size, threads, time_runs, time_rounds)
        ms = {"eval_mode": t, "prepared": t, "fast": t, "gpu": None}
    else:
        model = build(lambda m: m)
        ref = evaluate_tensors(model, test, n_cls, keep_predictions=keep)
        fast, res = scored_fast_path(
            lambda **kw: build(lambda m: fast_inference(m, **kw)),
            test,
            n_cls,
            ref.metrics["accuracy"],
        )
        paths = [model, build(prepare_for_inference), fast]
        times = interleaved_cpu_ms(paths, size, threads, time_runs, time_rounds)
        ms = dict(zip(("eval_mode", "prepared", "fast"), times, strict=True))
        ms["gpu"] = gpu_ms_per_image(model, size)
    row = {
        "checkpoint": " + ".join(str(m.path) for m in members),
        "arch": run.model.arch if len(members) == 1 else "ensemble",
        "task": run.task,
        "epoch": first.ckpt["epoch"] if len(members) == 1 else None,
        "seed": first.ckpt.get("seed") if len(members) == 1 else None,
        "config": first.ckpt["config"] if len(members) == 1 else None,
        "init": first.ckpt.get("init") if len(members) == 1 else None,
        "class_names": list(first.ckpt.get("class_names", [])),
        "n_test": len(test.y),
        "cm": ref.cm.tolist(),
        "metrics": ref.metrics,
        "fast_metrics": res.metrics,
        "bf16": bool(getattr(fast, "bf16", False)),
        "ms_per_image": ms,
        "threads": threads,
        "time_runs": time_runs,
        "time_rounds": time_rounds,
        "input_size": list(size),
        "canvas_mm": run.model.canvas_mm and list(run.model.canvas_mm),
        "train_data": first.ckpt.get("data"),
        "train_versions": first.ckpt.get("versions"),
        "test_data": str(data_path),
        "tta_views": views and list(views[0]),
        "int8": int8_note,
    }
    if len(members) > 1:
        row["members"] = [member_record(m) for m in members]
    if contacts is not None:
        row |= contact_scores(ref.predictions, test.y, contacts, run.task, n_cls)
    if run.task == "both":
        row |= {"class_cm": ref.class_cm.tolist(), "fast_class_cm": res.class_cm.tolist()}
    return row


def report_rows(row: dict) -> list[dict]:
    """The report's rows of one evaluated network: itself, or a class-and-parts network's two
    (a classify row over every test image, a segment row over the hands), each marked
    ``one_pass`` with the one pass's time."""
    if row["task"] != "both":
        return [row]
    classify = {**row, "task": "classify", "class_names": ["non_hand", "hand"], "one_pass": True}
    classify |= {"cm": row["class_cm"], "metrics": scores(row["class_cm"])}
    classify["fast_metrics"] = scores(row["fast_class_cm"])
    segment = {**row, "task": "segment", "one_pass": True}
    return [classify, segment]


def member_record(m: Member) -> dict:
    """What the report says of one network of an ensemble."""
    model = m.ckpt["config"]["model"]
    return {
        "checkpoint": str(m.path),
        "arch": model["arch"],
        "width": model.get("width"),
        "epoch": m.ckpt["epoch"],
        "seed": m.ckpt.get("seed"),
        "train_data": m.ckpt.get("data"),
    }


def scored_fast_path(
    make: Callable[..., nn.Module],
    test: TensorData,
    num_classes: int,
    ref_accuracy: float | None = None,
) -> tuple[nn.Module, EvalResult]:
    """The fast inference path and its test result. ``make(**kw)`` builds it with
    `learn.infer.fastpath.fast_inference`'s keywords: first bf16 where the CPU has it and its
    argmax agrees on 64 test images; if its accuracy then strays more than 0.5 points from eval
    mode's (``ref_accuracy``; None skips the check), float32, so the fast path keeps eval mode's
    predictions."""
    fast = make(check=test.x[:64])
    res = evaluate_tensors(fast, test, num_classes)
    if ref_accuracy is not None and abs(res.metrics["accuracy"] - ref_accuracy) > 0.005:
        fast = make(bf16=False)
        res = evaluate_tensors(fast, test, num_classes)
    return fast, res


_TEST_SPLIT: dict = {}  # key, tensors of the last test split read


def read_test_split(
    data_path: Path, run: RunConfig, hand_classes: tuple[str, ...] | None, progress: bool = True
) -> TensorData:
    """The test split of ``data_path`` in memory, as ``run`` reads it. The last one read is kept,
    so the rows of one ``handskin evaluate`` that share task, input size and canvas read it once;
    the key holds the files' size and modification time, so rewritten data is read afresh."""
    files = [data_path] if data_path.is_file() else _data_files(data_path)
    stamp = tuple((str(f), f.stat().st_mtime_ns, f.stat().st_size) for f in files)
    folder = (
        None if is_dataset(data_path) else (hand_classes and tuple(hand_classes), run.train.seed)
    )
    size, canvas = tuple(run.model.input_size), run.model.canvas_mm
    key = (str(data_path.resolve()), stamp, run.task, size, canvas and tuple(canvas), folder)
    if _TEST_SPLIT.get("key") != key:
        _TEST_SPLIT.clear()  # free the last split before reading the next
        split = open_split(data_path, "test", run.task, size, hand_classes, run.train.seed, canvas)
        _TEST_SPLIT.update(key=key, value=materialize(split, "test", progress))
    return _TEST_SPLIT["value"]


def _data_files(path: Path) -> list[Path]:
    """The files whose change means new data: a dataset's files, or an image folder's."""
    files = path.iterdir() if (path / DATASET).is_file() else path.rglob("*")
    return sorted(f for f in files if f.is_file())
