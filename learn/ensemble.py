"""Several trained networks of one task as one: the mean of their softmax outputs.

    members = load_members(["runs/fcn/best.pt", "runs/segnet/best.pt"])   # checked alike
    net = MeanSoftmax([m.model for m in members])   # x (B, 1, h, w) → log of the mean softmax

Averaging the class probabilities of networks that err in different places is the simplest
ensemble; on our hand prints the FCN-16s and SegNet mean beats either network alone
(docs/learning.md, "Ensembles"). The members must share the task, class names, class count,
input channels and input size, since one input image goes to all of them; :func:`load_members`
checks this before any work, naming the member that differs.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import torch
from torch import nn

from tactile.errors import ConfigError


class MeanSoftmax(nn.Module):
    """Networks averaged: forward x (B, C_in, h, w) → (B, C) or (B, C, h, w) float32, the log
    of the mean of the members' softmax outputs (so ``argmax`` gives the averaged decision
    and ``softmax`` the mean probability). A member may itself be a `learn.tta.FlipTTA`, whose
    log-probabilities the softmax turns back into its mean probability. Keeps the first
    member's ``num_classes``, ``in_channels``, ``task`` and ``input_size`` attributes, and
    ``bf16`` when every member runs in bfloat16."""

    def __init__(self, members: Sequence[nn.Module]) -> None:
        super().__init__()
        if len(members) < 2:
            raise ConfigError(f"an ensemble needs two or more networks; got {len(members)}")
        self.members = nn.ModuleList(members)
        for name in ("num_classes", "in_channels", "task", "input_size"):
            if hasattr(members[0], name):
                setattr(self, name, getattr(members[0], name))
        self.bf16 = all(bool(getattr(m, "bf16", False)) for m in members)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``(B, C_in, h, w)`` → log of the mean softmax, ``(B, C)`` or ``(B, C, h, w)``."""
        mean = torch.stack([m(x).float().softmax(1) for m in self.members]).mean(0)
        return mean.clamp_min(torch.finfo(mean.dtype).tiny).log()


@dataclass
class Member:
    """One network of an ensemble: its checkpoint file and dict, model (eval mode) and
    ``learn.train.RunConfig``."""

    path: Path
    ckpt: dict
    model: nn.Module
    run: object


#: What every member must share, (description, value of a Member).
SHARED = (
    ("task", lambda m: m.run.task),
    ("class count", lambda m: m.run.model.num_classes),
    ("class names", lambda m: tuple(m.ckpt.get("class_names") or ())),
    ("input channels", lambda m: m.run.model.in_channels),
    ("input size (h, w) px", lambda m: tuple(m.run.model.input_size)),
    ("input canvas (h, w) mm", lambda m: m.run.model.canvas_mm),
)


def check_members(members: Sequence[Member]) -> None:
    """ConfigError naming the first member that differs from the first in anything of
    `SHARED`, and the fix; also for fewer than two members or one file given twice."""
    if len(members) < 2:
        raise ConfigError(
            f"an ensemble needs two or more checkpoints; got {len(members)}. "
            "Fix: give two or more .pt files of one task"
        )
    seen = [m.path.resolve() for m in members]
    if len(set(seen)) < len(seen):
        raise ConfigError(
            "an ensemble lists one checkpoint twice, which weights it double. "
            "Fix: give each .pt file once"
        )
    first = members[0]
    for what, get in SHARED:
        for m in members[1:]:
            if get(m) != get(first):
                raise ConfigError(
                    f"ensemble members differ in {what}: {first.path} has {get(first)!r}, "
                    f"{m.path} has {get(m)!r}. Fix: average only networks trained for the same "
                    "task, classes, input size and canvas"
                )


def load_members(paths: Sequence[str | Path], int8_ok: bool = False) -> list[Member]:
    """The checkpoints of an ensemble, loaded and checked alike (`check_members`); int8 files
    refused unless ``int8_ok`` (`learn.checkpoint.model_from_checkpoint`)."""
    from learn.checkpoint import load_checkpoint, model_from_checkpoint
    from learn.int8_file import refuse_int8

    members = []
    for p in paths:
        ckpt = load_checkpoint(p)
        if not int8_ok:
            refuse_int8(ckpt, p, "an ensemble averages float networks")
        model, run = model_from_checkpoint(ckpt, int8_ok=True)
        members.append(Member(Path(p), ckpt, model, run))
    check_members(members)
    return members
