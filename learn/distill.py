"""Knowledge distillation (Hinton, Vinyals & Dean, 2015): a classifier trained against a trained
teacher's softened probabilities beside the labels (``RunConfig.distill_from``).

A deep classifier (VGG16 w0.25, 1.7 ms per image) recognises more hands than HandsNet (1.0 ms)
on the same data; distillation asks whether the small network can learn the large one's
decisions. Before training, the teacher scores every training image once in each view the
student trains on (the paper's flips), and the mean of its probabilities at temperature ``T``
over those views (its test-time-flip prediction, `learn.tta`) is that sample's soft target in
every view. Each step's loss is then

    (1 - a) * CE(student logits, labels) + a * T^2 * KL(teacher_T || softmax(student logits / T))

with ``a = distill_weight``; ``T^2`` keeps the soft term's gradients at the hard term's scale.
Validation losses and metrics are the student's own, without the teacher.

    distiller = make_distiller(run, data, progress=True)   # None when run.distill_from is ""
    loss = distiller.loss(ce, logits, samples)               # samples (B,) indices into data.train

The teacher must be a classifier of the student's classes, input size and canvas, and must not
have trained on the student's test people or objects (`learn.leakage`): :func:`check_teacher`
refuses it before any work, naming the fix.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import torch
from torch import nn
from tqdm.auto import tqdm

from learn.checkpoint import load_checkpoint, model_from_checkpoint
from learn.tta import flip_view
from tactile.errors import ConfigError, DataError


@dataclass
class Distiller:
    """A teacher's soft targets and how much they weigh.

    probs : (S, C) float32, the teacher's probabilities at ``temperature`` for each training
        sample, averaged over the student's training views (rows sum to 1).
    weight : share ``a`` in (0, 1] of the loss given to the teacher. temperature : ``T`` > 0.
    """

    probs: torch.Tensor
    weight: float
    temperature: float

    def loss(self, hard: torch.Tensor, logits: torch.Tensor, samples: torch.Tensor) -> torch.Tensor:
        """``(1 - a) * hard + a * T^2 * KL(teacher_T || student_T)`` (scalar), the KL averaged
        over the batch. hard : the labels' loss (scalar); logits : (B, C) float32; samples :
        (B,) int64 training-sample indices (views share their sample's target)."""
        t = self.temperature
        target = self.probs[samples.to(self.probs.device)].to(logits.device)
        log_q = nn.functional.log_softmax(logits / t, dim=1)
        soft = nn.functional.kl_div(log_q, target, reduction="batchmean") * t * t
        return (1.0 - self.weight) * hard + self.weight * soft


def check_teacher(run, data_path: str | Path | None) -> dict:
    """The teacher's checkpoint dict, once it is known to fit ``run`` (a ``RunConfig`` with
    ``distill_from``) trained on ``data_path``; ConfigError / DataError naming the fix when the
    file is missing, is not a classifier of the student's classes and input, or has trained on
    people or objects in ``data_path``'s test split. Warns when it trained on the same dataset
    with another validation split (it has then seen some of the student's validation people)."""
    from learn.leakage import lineage, shared_groups
    from learn.run_config import run_from_dict

    path = Path(run.distill_from)
    if not path.is_file():
        raise DataError(
            f"distill_from: no teacher checkpoint at {path}. Fix: give a best.pt of "
            'handskin train (e.g. --arch vgg16), or distill_from = "" (off)'
        )
    ckpt = load_checkpoint(path)
    theirs = run_from_dict(ckpt["config"])
    mine = run.model
    wrong = [
        f"{name} {a} (the student's: {b})"
        for name, a, b in (
            ("task", theirs.task, run.task),
            ("num_classes", theirs.model.num_classes, mine.num_classes),
            ("input_size", tuple(theirs.model.input_size), tuple(mine.input_size)),
            ("canvas_mm", theirs.model.canvas_mm, mine.canvas_mm),
        )
        if a != b
    ]
    if wrong:
        raise ConfigError(
            f"distill_from {path}: the teacher's {'; '.join(wrong)} differ. Fix: "
            "a teacher trained for the same task, classes, input_size and canvas"
        )
    trained_on = (ckpt.get("data") or {}).get("path")
    learned = [r["path"] for r in lineage(ckpt)]  # its data and its own starts' and teachers'
    if data_path is not None and learned:
        shared = shared_groups(learned, data_path)
        if shared and shared["test_samples"]:
            raise ConfigError(
                f"distill_from {path}: the teacher learned from {', '.join(map(str, learned))}, "
                "which share "
                f"{len(shared['subjects'])} subjects and {len(shared['instances'])} object "
                f"instances with {shared['test_samples']} test samples of {data_path}, so the "
                "student would learn its test people. Fix: a teacher trained on this dataset"
            )
        same = trained_on and Path(trained_on).resolve() == Path(data_path).resolve()
        if same and (theirs.train.seed, theirs.val_fraction) != (run.train.seed, run.val_fraction):
            warnings.warn(
                f"distill_from {path}: the teacher's validation split (seed "
                f"{theirs.train.seed}, val_fraction {theirs.val_fraction}) is not the student's, "
                "so it trained on some of the student's validation people and the best epoch "
                "is picked on people the teacher knows. Give the student the teacher's seed to "
                "avoid it",
                stacklevel=2,
            )
    return ckpt


@torch.no_grad()
def teacher_probs(
    teacher: nn.Module,
    x: torch.Tensor,
    views: torch.Tensor,
    temperature: float,
    batch_size: int = 256,
    device: str = "cpu",
    progress: bool = False,
) -> torch.Tensor:
    """(S, C) float32: the mean over ``views`` (ids of `learn.tta.VIEW_DIMS`) of
    ``softmax(teacher(view of x) / temperature)`` for images ``x`` (S, 1, h, w)."""
    teacher = teacher.eval().to(device)
    out = []
    bar = tqdm(range(0, len(x), batch_size), desc="teacher", leave=False, disable=not progress)
    for start in bar:
        batch = x[start : start + batch_size].to(device)
        views_p = [
            (
                teacher(
                    flip_view(batch, int(v)).contiguous(memory_format=torch.channels_last)
                ).float()
                / temperature
            ).softmax(1)
            for v in views
        ]
        out.append(torch.stack(views_p).mean(0).cpu())
    return torch.cat(out)


def make_distiller(
    run, data, progress: bool = True, checked: dict | None = None
) -> Distiller | None:
    """The run's :class:`Distiller` over ``data.train`` (a ``learn.folder.Data``), or None when
    ``run.distill_from`` is empty. The teacher runs in float32 on ``run.device``. ``checked``:
    the dict :func:`check_teacher` already returned for this run and data (not loaded again)."""
    if not run.distill_from:
        return None
    from learn.train import views_of

    ckpt = checked if checked is not None else check_teacher(run, data.description.get("path"))
    teacher, _ = model_from_checkpoint(ckpt)
    teacher = teacher.to(memory_format=torch.channels_last)
    probs = teacher_probs(
        teacher,
        data.train.x,
        views_of(run),
        run.distill_temperature,
        run.eval_batch_size,
        run.device,
        progress,
    )
    if not torch.isfinite(probs).all():
        raise DataError(
            f"distill_from {run.distill_from}: the teacher's probabilities are not "
            "finite. Fix: a teacher checkpoint that evaluates (handskin evaluate)"
        )
    return Distiller(probs.to(run.device), run.distill_weight, run.distill_temperature)
