"""A linear SVM as plain arrays, and the model file of the classical baselines: one ``.npz``
read with ``allow_pickle=False`` (no joblib, no pickle), a JSON ``meta`` string (kind,
configuration, input size, class names, seed, versions, data) and plain arrays (the vocabulary,
the SVM's coefficients and intercepts, the feature scaler, and for VGG + SVM the network's
weights)."""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tactile.errors import DataError

CLASSICAL = ("bovw", "vgg_svm")
MODEL_FILE = "model.npz"  # file name in a run folder


@dataclass(frozen=True)
class LinearSvm:
    """A fitted linear SVM as arrays. coef : (C', D) float64, intercept : (C',) float64,
    classes : (C,) int64 (C' = 1 for two classes, else C; one-vs-rest as sklearn's LinearSVC)."""

    coef: np.ndarray
    intercept: np.ndarray
    classes: np.ndarray

    @classmethod
    def from_sklearn(cls, svc) -> LinearSvm:
        """The arrays of a fitted ``sklearn.svm.LinearSVC``."""
        return cls(
            np.asarray(svc.coef_, np.float64),
            np.asarray(svc.intercept_, np.float64),
            np.asarray(svc.classes_, np.int64),
        )

    def decision_function(self, features: np.ndarray) -> np.ndarray:
        """Scores of ``features`` (S, D): (S,) for two classes, (S, C) otherwise."""
        scores = np.asarray(features, np.float64) @ self.coef.T + self.intercept
        return scores[:, 0] if len(self.coef) == 1 else scores

    def predict(self, features: np.ndarray) -> np.ndarray:
        """(S,) class ids of ``features`` (S, D)."""
        return self.classes_of(self.decision_function(features))

    def classes_of(self, scores: np.ndarray) -> np.ndarray:
        """(S,) class ids of `decision_function` scores (LinearSVC's rule: score > 0 for two
        classes, else the argmax)."""
        pick = (scores > 0).astype(np.int64) if scores.ndim == 1 else scores.argmax(axis=1)
        return self.classes[pick]

    def arrays(self) -> dict[str, np.ndarray]:
        """``{"svm_coef", "svm_intercept", "svm_classes"}`` for :func:`save_npz`."""
        return {"svm_coef": self.coef, "svm_intercept": self.intercept, "svm_classes": self.classes}

    @classmethod
    def from_arrays(cls, arrays: Mapping[str, np.ndarray]) -> LinearSvm:
        """Inverse of :meth:`arrays`."""
        return cls(arrays["svm_coef"], arrays["svm_intercept"], arrays["svm_classes"])


def save_npz(path: str | Path, meta: Mapping, arrays: Mapping[str, np.ndarray]) -> Path:
    """Write ``meta`` (JSON) and ``arrays`` to ``path`` atomically (temporary name, replace)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.tmp.npz")
    np.savez_compressed(tmp, meta=np.array(json.dumps(meta)), **arrays)
    os.replace(tmp, path)
    return path


def load_npz(path: str | Path) -> tuple[dict, dict[str, np.ndarray]]:
    """(meta, arrays) of a model file; DataError naming the file and the fix."""
    path = Path(path)
    if not path.is_file():
        raise DataError(
            f"no model file at {path}. Fix: give a model.npz written by "
            "handskin train --arch bovw or --arch vgg_svm"
        )
    try:
        with np.load(path, allow_pickle=False) as npz:
            arrays = {k: npz[k] for k in npz.files}
        meta = json.loads(str(arrays.pop("meta")))
    except (OSError, ValueError, KeyError) as err:
        raise DataError(
            f"{path} is not a handskin classical model ({err}). Fix: write it "
            "with handskin train --arch bovw or --arch vgg_svm"
        ) from err
    if meta.get("kind") not in CLASSICAL:
        raise DataError(
            f"{path}: unknown model kind {meta.get('kind')!r}; known: {', '.join(CLASSICAL)}"
        )
    return meta, arrays
