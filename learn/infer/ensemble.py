"""Networks averaged: a network over its flipped views (test-time flips), and several networks
of one task as one (an ensemble), both as the mean of softmax outputs.

    tta = FlipTTA(model, views=(0, 1, 2))   # original, columns reversed, rows reversed
    members = load_members(["runs/fcn/best.pt", "runs/segnet/best.pt"])   # checked alike
    net = MeanSoftmax([m.model for m in members])   # x (B, 1, h, w) → log of the mean softmax

Test-time flips: each view of the input is one flip (`learn.inputs.VIEW_DIMS`); a segmenter's
output is flipped back before the mean, so every pixel averages the class probabilities it got
in each view. The views go through the network as one batch. A network trained with flips has
seen each view; flips also mirror a hand, so the mean pools a right-hand and a left-hand reading
of one print. Outputs are the log of the mean probability: ``argmax`` gives the averaged
decision, ``softmax`` the mean probability.

Averaging the class probabilities of networks that err in different places is the simplest
ensemble; on our hand prints the FCN-16s and SegNet mean beats either network alone
(docs/findings.md). The members must share the task, class names, class count,
input channels and input size, since one input image goes to all of them; :func:`load_members`
checks this before any work, naming the member that differs.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import torch
from torch import nn

from learn.config import RunConfig
from learn.inputs import PAPER_VIEWS, VIEW_DIMS, flip_view
from learn.train.checkpoint import load_checkpoint, model_from_checkpoint, refuse_int8
from tactile.errors import ConfigError


class FlipTTA(nn.Module):
    """``model`` with test-time flips over ``views`` (two or more ids of `learn.inputs.VIEW_DIMS`).

    forward: x (B, 1, h, w) → (B, C) or (B, C, h, w) float32, the log of the mean softmax over
    the views. Keeps the wrapped model's ``num_classes``, ``in_channels``, ``task`` and
    ``input_size`` attributes.
    """

    def __init__(self, model: nn.Module, views: Sequence[int] = (0, 1, 2)) -> None:
        super().__init__()
        views = tuple(int(v) for v in views)
        if len(views) < 2 or len(set(views)) != len(views) or set(views) - set(VIEW_DIMS):
            raise ValueError(f"views {views}: give two or more distinct ids of {set(VIEW_DIMS)}")
        self.net, self.views = model, views
        for name in ("num_classes", "in_channels", "task", "input_size", "bf16"):
            if hasattr(model, name):
                setattr(self, name, getattr(model, name))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``(B, C_in, h, w)`` → log of the mean softmax, ``(B, C)`` or ``(B, C, h, w)``."""
        n = len(x)
        out = self.net(torch.cat([flip_view(x, v) for v in self.views])).float().softmax(1)
        probs = out.split(n)
        if out.ndim == 4:  # a segmenter: flip each view's output back onto the input's pixels
            probs = [flip_view(p, v) for p, v in zip(probs, self.views, strict=True)]
        mean = torch.stack(list(probs)).mean(0)
        return mean.clamp_min(torch.finfo(mean.dtype).tiny).log()


def tta_views(run: RunConfig, ckpt_path: str | Path) -> tuple[int, ...]:
    """The views a network was trained on, for test-time flips; a ConfigError when it was
    trained on the original view only."""
    if not run.flips:
        raise ConfigError(
            f"{ckpt_path} was trained without flips (flips = false), so test-time flips would "
            "show it views it never saw. Fix: evaluate it without --tta"
        )
    return PAPER_VIEWS


class MeanSoftmax(nn.Module):
    """Networks averaged: forward x (B, C_in, h, w) → (B, C) or (B, C, h, w) float32, the log
    of the mean of the members' softmax outputs (so ``argmax`` gives the averaged decision
    and ``softmax`` the mean probability). A member may itself be a `FlipTTA`, whose
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
    RunConfig."""

    path: Path
    ckpt: dict
    model: nn.Module
    run: RunConfig


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
    refused unless ``int8_ok``."""
    members = []
    for p in paths:
        ckpt = load_checkpoint(p)
        if not int8_ok:
            refuse_int8(ckpt, p, "an ensemble averages float networks")
        model, run = model_from_checkpoint(ckpt, int8_ok=True, where=p)
        members.append(Member(Path(p), ckpt, model, run))
    check_members(members)
    return members
