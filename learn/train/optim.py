"""Optimisers and fine-tuning: any checkpoint loaded into a model, per-layer learning-rate
factors, the step schedule, and the check of ``--init`` made before any work.

Selectors name groups of parameters for lr factors (the paper's Test C multiplies the lr of the
first two convolutional layers by 0.1):
- ``"first_two_convs"`` / ``"first_<n>_convs"``: weights and biases of the first n ``Conv2d``
  modules in registration order (the input side of every network here);
- ``"last_layer"``: the last ``Conv2d`` / ``Linear`` module (the classifier / score layer);
- any other string is a ``fnmatch`` pattern on parameter names (``"encoder.stages.0.*"``).
A parameter takes the factor of the first selector that matches it, else 1; factor 0 freezes it.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass
from fnmatch import fnmatchcase
from pathlib import Path

import torch
from torch import nn

from learn.config import RunConfig, TrainConfig
from learn.models import create_model
from learn.train.checkpoint import load_checkpoint
from tactile.errors import ConfigError, DataError


@dataclass(frozen=True)
class LoadReport:
    """What :func:`load_weights` did: parameter / buffer names of the model."""

    loaded: tuple[str, ...]  # copied from the checkpoint
    shape_mismatch: tuple[str, ...]  # in both but of another shape: left as initialised
    missing: tuple[str, ...]  # in the model only: left as initialised
    unexpected: tuple[str, ...]  # in the checkpoint only (after renaming): ignored

    def summary(self) -> str:
        """``"<k> of <n> tensors loaded; <top-level modules> start fresh"``."""
        fresh = sorted({k.split(".")[0] for k in self.missing + self.shape_mismatch})
        n = len(self.loaded) + len(self.missing) + len(self.shape_mismatch)
        return f"{len(self.loaded)} of {n} tensors loaded" + (
            f"; {', '.join(fresh)} start fresh" if fresh else ""
        )


def read_state_dict(source: str | Path | Mapping) -> dict[str, torch.Tensor]:
    """The model state of a checkpoint file or dict: ``{"model": state}`` or a bare state dict."""
    ckpt = torch.load(source, map_location="cpu") if isinstance(source, str | Path) else source
    state = ckpt.get("model", ckpt) if isinstance(ckpt, Mapping) else None
    if not isinstance(state, Mapping) or not all(torch.is_tensor(v) for v in state.values()):
        raise DataError(f"{source!s:.80}: not a checkpoint dict with a 'model' state dict")
    return dict(state)


@torch.no_grad()
def load_weights(
    model: nn.Module, source: str | Path | Mapping, rename: Mapping[str, str] | None = None
) -> LoadReport:
    """Copy every checkpoint tensor whose (renamed) name and shape match into ``model``.

    ``rename`` maps checkpoint name prefixes to model prefixes (``{"features.": "encoder."}``).
    A VGG16 classifier's ``encoder.*`` loads into SegNet / FCN-16s as is; a head of another
    class count is reported in ``shape_mismatch`` and keeps its fresh initialisation.
    """
    state = read_state_dict(source)
    for old, new in (rename or {}).items():
        state = {new + k[len(old) :] if k.startswith(old) else k: v for k, v in state.items()}
    own = model.state_dict()
    loaded = [k for k in own if k in state and state[k].shape == own[k].shape]
    for k in loaded:
        own[k].copy_(state[k])
    return LoadReport(
        loaded=tuple(loaded),
        shape_mismatch=tuple(k for k in own if k in state and k not in loaded),
        missing=tuple(k for k in own if k not in state),
        unexpected=tuple(k for k in state if k not in own),
    )


def _selected(model: nn.Module, selector: str) -> set[str]:
    """Parameter names a selector picks (see the module docstring)."""
    match = re.fullmatch(r"first_(two|\d+)_convs", selector)
    if match:
        n = 2 if match[1] == "two" else int(match[1])
        convs = [name for name, m in model.named_modules() if isinstance(m, nn.Conv2d)][:n]
        return {f"{c}.{p}" for c in convs for p, _ in model.get_submodule(c).named_parameters()}
    if selector == "last_layer":
        last = [name for name, m in model.named_modules() if isinstance(m, nn.Conv2d | nn.Linear)]
        return {f"{last[-1]}.{p}" for p, _ in model.get_submodule(last[-1]).named_parameters()}
    return {name for name, _ in model.named_parameters() if fnmatchcase(name, selector)}


def lr_factors_by_parameter(model: nn.Module, lr_factors: Mapping[str, float]) -> dict[str, float]:
    """Factor of every parameter name (first matching selector wins, default 1)."""
    factors: dict[str, float] = {}
    for selector, factor in lr_factors.items():
        chosen = _selected(model, selector)
        if not chosen:
            raise ConfigError(
                f"lr factor selector {selector!r} matches no parameter; use first_two_convs, "
                "first_<n>_convs, last_layer or an fnmatch pattern on parameter names"
            )
        factors.update({name: factor for name in chosen if name not in factors})
    return {name: factors.get(name, 1.0) for name, _ in model.named_parameters()}


def param_groups(
    model: nn.Module, base_lr: float, lr_factors: Mapping[str, float] | None = None
) -> list[dict]:
    """Optimizer parameter groups, one per factor: ``{"params", "lr", "lr_factor"}``.

    Parameters with factor 0 are frozen (``requires_grad`` off) and left out, as are those
    already frozen (e.g. FCN-16s's fixed bilinear upsampler).
    """
    by_name = lr_factors_by_parameter(model, lr_factors or {})
    groups: dict[float, list[nn.Parameter]] = {}
    for name, p in model.named_parameters():
        if by_name[name] == 0:
            p.requires_grad_(False)
        if p.requires_grad:
            groups.setdefault(by_name[name], []).append(p)
    return [{"params": ps, "lr": base_lr * f, "lr_factor": f} for f, ps in groups.items()]


def make_optimizer(model: nn.Module, cfg: TrainConfig) -> torch.optim.Optimizer:
    """SGD with momentum, Adam (L2 in the gradient) or AdamW (decay decoupled from the gradient,
    Loshchilov & Hutter 2019) over :func:`param_groups` with ``cfg.lr_factors``."""
    groups = param_groups(model, cfg.lr, cfg.lr_factors)
    if cfg.optimizer == "adamw":
        return torch.optim.AdamW(groups, lr=cfg.lr, weight_decay=cfg.weight_decay)
    if cfg.optimizer == "adam":
        return torch.optim.Adam(groups, lr=cfg.lr, weight_decay=cfg.weight_decay)
    return torch.optim.SGD(groups, lr=cfg.lr, momentum=cfg.momentum, weight_decay=cfg.weight_decay)


def make_scheduler(
    optimizer: torch.optim.Optimizer, cfg: TrainConfig
) -> torch.optim.lr_scheduler.StepLR:
    """Step schedule, stepped once per epoch: lr × ``lr_drop_factor`` every period epochs."""
    return torch.optim.lr_scheduler.StepLR(
        optimizer, step_size=cfg.lr_drop_period_epochs, gamma=cfg.lr_drop_factor
    )


def check_init(run: RunConfig, init: str | Path) -> tuple[LoadReport, dict]:
    """What ``--init`` ``init`` (a .pt checkpoint) loads into ``run``'s network, checked before
    any data are read, and the loaded checkpoint (so it is read once). ConfigError naming the
    fix when none of its tensors fits (another architecture, width or class count)."""
    ckpt = load_checkpoint(init)
    report = load_weights(create_model(run.model.arch, **run.model.kwargs()), ckpt)
    if not report.loaded:
        theirs = (ckpt.get("config") or {}).get("model") or {}
        raise ConfigError(
            f"--init {init}: none of its {len(ckpt['model'])} tensors fits a {run.model.arch} "
            f"of width {run.model.width} and {run.model.num_classes} classes (it holds a "
            f"{theirs.get('arch', 'unknown')} of width {theirs.get('width')}). Fix: a checkpoint "
            "of the same network and width, or a vgg16 classifier of the same width for "
            "segnet / fcn16s (its encoder loads)"
        )
    return report, ckpt
