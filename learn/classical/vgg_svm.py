"""VGG16 features + linear SVM (C = 0.25): the paper's transfer-learning classifier variant."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch
from sklearn.svm import LinearSVC

from learn.classical.svm import LinearSvm
from learn.config import VggSvmConfig, run_from_dict
from learn.models import create_model
from learn.models.vgg import VGGClassifier
from learn.numerics import flushing
from learn.train.checkpoint import load_checkpoint, model_from_checkpoint
from tactile.config import from_dict
from tactile.errors import ConfigError, DataError

Images = Sequence[np.ndarray] | np.ndarray | torch.Tensor


def images_to_tensor(images: Images, in_channels: int = 1) -> torch.Tensor:
    """``(N, H, W)`` or ``(N, 1, H, W)`` grey images → ``(N, in_channels, H, W)`` float32.

    uint8 images are scaled to [0, 1] (÷ 255); float images are taken as already in [0, 1].
    Grey is repeated over the channels for a 3-channel network.
    """
    arr = images if torch.is_tensor(images) else torch.as_tensor(np.stack(list(images)))
    x = arr.float() / 255.0 if arr.dtype == torch.uint8 else arr.float()
    if x.ndim == 3:
        x = x[:, None]
    if x.ndim != 4 or x.shape[1] != 1:
        raise DataError(f"expected (N, H, W) or (N, 1, H, W) grey images, got {tuple(x.shape)}")
    return x.expand(-1, in_channels, -1, -1)


@torch.no_grad()
@flushing()  # a trained VGG16 may hold subnormal weights
def extract_features(
    model: VGGClassifier,
    images: Images,
    layer: str = "fc7",
    batch_size: int = 64,
    device: str | torch.device = "cpu",
) -> np.ndarray:
    """``(N, D)`` float32 features of ``layer`` ("fc7" or "pool5"), model in eval mode."""
    model = model.to(device).eval()
    x = images_to_tensor(images, model.in_channels)
    chunks = [
        model.features(x[i : i + batch_size].to(device), layer).cpu()
        for i in range(0, len(x), batch_size)
    ]
    return torch.cat(chunks).numpy()


class VggSvmClassifier:
    """A frozen VGG16-style network as feature extractor and a linear SVM on its features.

    ``fit(images, labels)`` / ``predict(images)``; images as in :func:`images_to_tensor`.
    Features are standardised first when ``cfg.standardize`` (SVMs are scale-sensitive): the
    mean and scale (D,) are kept as arrays, the SVM as ``learn.classical.LinearSvm``, so that
    ``to_arrays`` / ``from_arrays`` save and restore the exact model (weights included) without
    pickle. ``seed`` seeds the LinearSVC solver.
    """

    def __init__(
        self,
        model: VGGClassifier,
        cfg: VggSvmConfig | None = None,
        device: str = "cpu",
        *,
        seed: int = 0,
        run_config: dict | None = None,
    ) -> None:
        self.model, self.cfg, self.device = model.eval(), cfg or VggSvmConfig(), device
        self.seed, self.run_config = seed, run_config
        self.mean: np.ndarray | None = None  # (D,) feature mean (0 without standardisation)
        self.scale: np.ndarray | None = None  # (D,) feature sd (1 where 0 or not standardised)
        self.svm: LinearSvm | None = None

    @classmethod
    def from_checkpoint(
        cls, path: str | Path, cfg: VggSvmConfig | None = None, *, seed: int = 0
    ) -> VggSvmClassifier:
        """Features of a vgg16 checkpoint written by ``handskin train --arch vgg16``."""
        ckpt = load_checkpoint(path)
        model, run = model_from_checkpoint(ckpt, where=path)
        if run.model.arch != "vgg16":
            raise ConfigError(
                f"{path} is a {run.model.arch} checkpoint; VGG16 + SVM needs a "
                "vgg16 one (handskin train --arch vgg16)"
            )
        if run.model.canvas_mm is not None:
            raise ConfigError(
                f"{path} centres its inputs on a {run.model.canvas_mm} mm canvas; "
                "VGG16 + SVM reads images stretched to the input. Fix: a VGG16 "
                "trained without model.canvas_mm"
            )
        return cls(model, cfg, seed=seed, run_config=ckpt["config"])

    @property
    def input_size(self) -> tuple[int, int]:
        """(h, w) px of the network's input (from its run configuration; else 68 x 100)."""
        size = ((self.run_config or {}).get("model") or {}).get("input_size", (68, 100))
        return int(size[0]), int(size[1])

    def features(self, images: Images) -> np.ndarray:
        """``(N, D)`` features of the configured layer."""
        return extract_features(
            self.model, images, self.cfg.feature_layer, self.cfg.batch_size, self.device
        )

    def _scaled(self, features: np.ndarray) -> np.ndarray:
        return (np.asarray(features, np.float64) - self.mean) / self.scale

    def fit(self, images: Images, labels: np.ndarray) -> VggSvmClassifier:
        """Extract features and fit the SVM; returns ``self``."""
        feats = np.asarray(self.features(images), np.float64)
        self.mean, self.scale = np.zeros(feats.shape[1]), np.ones(feats.shape[1])
        if self.cfg.standardize:
            sd = feats.std(axis=0)
            self.mean, self.scale = feats.mean(axis=0), np.where(sd > 0, sd, 1.0)
        svc = LinearSVC(C=self.cfg.svm_c, random_state=self.seed)
        self.svm = LinearSvm.from_sklearn(svc.fit(self._scaled(feats), np.asarray(labels)))
        return self

    def svm_or_fail(self) -> LinearSvm:
        """The fitted SVM (DataError before ``fit``)."""
        if self.svm is None:
            raise DataError("VggSvmClassifier: call fit() before predict()")
        return self.svm

    def decision_function(self, images: Images) -> np.ndarray:
        """SVM scores: ``(N,)`` for two classes, ``(N, C)`` otherwise."""
        return self.svm_or_fail().decision_function(self._scaled(self.features(images)))

    def predict(self, images: Images) -> np.ndarray:
        """``(N,)`` predicted labels."""
        return self.svm_or_fail().predict(self._scaled(self.features(images)))

    def to_arrays(self) -> tuple[dict, dict[str, np.ndarray]]:
        """(configuration: VggSvmConfig fields and the network's run config; arrays: the SVM,
        ``mean`` / ``scale`` (D,) and the network's weights as ``vgg.<state-dict name>``)."""
        svm = self.svm_or_fail()
        weights = {f"vgg.{k}": v.detach().cpu().numpy() for k, v in self.model.state_dict().items()}
        cfg = {**asdict(self.cfg), "seed": self.seed, "vgg_run": self.run_config}
        return cfg, {"mean": self.mean, "scale": self.scale, **svm.arrays(), **weights}

    @classmethod
    def from_arrays(cls, meta: dict, arrays: dict[str, np.ndarray]) -> VggSvmClassifier:
        """The model :meth:`to_arrays` described (network rebuilt from its run config)."""
        cfg = dict(meta["config"])
        seed, run_config = cfg.pop("seed"), cfg.pop("vgg_run")
        run = run_from_dict(run_config)
        model = create_model(run.model.arch, **run.model.kwargs())
        model.load_state_dict(
            {
                k[4:]: torch.from_numpy(np.array(v))
                for k, v in arrays.items()
                if k.startswith("vgg.")
            }
        )
        out = cls(model, from_dict(VggSvmConfig, cfg), seed=seed, run_config=run_config)
        out.mean, out.scale = arrays["mean"], arrays["scale"]
        out.svm = LinearSvm.from_arrays(arrays)
        return out
