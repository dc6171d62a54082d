"""VGG16 features + linear SVM (C = 0.25): the paper's transfer-learning classifier variant."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
from sklearn.pipeline import Pipeline, make_pipeline
from sklearn.preprocessing import StandardScaler
from sklearn.svm import LinearSVC

from learn.config import VggSvmConfig
from learn.models.vgg import VGGClassifier
from tactile.errors import DataError

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
    """A frozen VGG16-style network as feature extractor and a ``LinearSVC`` on its features.

    ``fit(images, labels)`` / ``predict(images)``; images as in :func:`images_to_tensor`.
    Features are standardised first when ``cfg.standardize`` (SVMs are scale-sensitive).
    """

    def __init__(
        self, model: VGGClassifier, cfg: VggSvmConfig | None = None, device: str = "cpu"
    ) -> None:
        self.model, self.cfg, self.device = model, cfg or VggSvmConfig(), device
        self.svm: Pipeline | None = None

    def features(self, images: Images) -> np.ndarray:
        """``(N, D)`` features of the configured layer."""
        return extract_features(
            self.model, images, self.cfg.feature_layer, self.cfg.batch_size, self.device
        )

    def fit(self, images: Images, labels: np.ndarray) -> VggSvmClassifier:
        """Extract features and fit the SVM; returns ``self``."""
        steps = [StandardScaler()] if self.cfg.standardize else []
        self.svm = make_pipeline(*steps, LinearSVC(C=self.cfg.svm_c, random_state=0))
        self.svm.fit(self.features(images), np.asarray(labels))
        return self

    def _fitted(self) -> Pipeline:
        if self.svm is None:
            raise DataError("VggSvmClassifier: call fit() before predict()")
        return self.svm

    def decision_function(self, images: Images) -> np.ndarray:
        """SVM scores: ``(N,)`` for two classes, ``(N, C)`` otherwise."""
        return self._fitted().decision_function(self.features(images))

    def predict(self, images: Images) -> np.ndarray:
        """``(N,)`` predicted labels."""
        return self._fitted().predict(self.features(images))
