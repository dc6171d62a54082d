"""Test A (blind spots) and Test B (taxel removal) for any number of trained networks at once.

    models = [Predictor.load("HandsNet", "clf.pt"), Predictor.load("SegNet", "seg.pt")]
    a = blind_spot_study(frames, models, [(1, 10.0), (4, 40.0)], n_patterns=10, seed=0)
    b = removal_study(frames, models, [0.1, 0.3, 0.6], n_patterns=10, seed=0)

Every pattern regenerates the images of the rows it changes through the corrupted map and runs
every network on them (batches of 64 under ``torch.no_grad``); the images are made once per
pattern and shared by all networks. Under blind spots a frame none of whose pressed taxels is
blind gives the very same image, so only the affected rows are run again (the others keep the
zero-corruption prediction). Each pattern yields one confusion matrix per network, pooled over
the rows; scores are computed per pattern and summarised over patterns.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch
from tqdm.auto import tqdm

from learn import metrics as M
from learn.checkpoint import load_checkpoint, model_from_checkpoint
from learn.evaluate import logits_of
from learn.experiments.robustness_data import (
    CHUNK,
    KEY_REMOVAL,
    KEY_SPOTS,
    Frames,
    net_inputs,
    net_labels,
    stream,
)
from learn.experiments.robustness_maps import (
    IGNORE,
    discarded_hand_pixels,
    rebuild,
    spot_pattern,
    warp_labels,
)
from learn.inputs import input_canvas, unpressed_as_background
from learn.models import prepare_for_inference
from tactile.errors import ConfigError
from tactile.faults import nested_removal, zero_taxels
from tactile.labels import label_image

BATCH = 64  # images per forward pass
SEG_KEYS = ("pixel_accuracy", "mean_accuracy", "mean_iou", "fw_iou")


class Predictor:
    """A trained network as a function of network inputs (B, 1, h, w) -> class ids.

    name : label in tables. task : "classify" (2 classes: non-hand, hand) or "segment"
    (7 classes). size : (h, w) px input. num_classes : int. fast : predict with batch norms
    folded into the convolutions, channels-last (``learn.models.prepare_for_inference``;
    1.5-2.5x faster on a CPU, the same class up to float rounding); False: the eval-mode model.
    """

    def __init__(self, name: str, model: torch.nn.Module, run, fast: bool = True) -> None:
        self.name, self.model, self.task = name, model.eval(), run.task
        self.net = prepare_for_inference(model) if fast else self.model
        self.size, self.num_classes = tuple(run.model.input_size), run.model.num_classes
        self.canvas_mm = run.model.canvas_mm  # (H, W) mm or None (ModelConfig.canvas_mm)
        want = 2 if self.task == "classify" else 7
        if self.num_classes != want:
            raise ConfigError(
                f"{name}: a {self.task} network needs {want} classes for the "
                f"robustness tests, this one has {self.num_classes}"
            )

    @classmethod
    def load(cls, name: str, path, fast: bool = True) -> Predictor:
        """The network of a checkpoint (.pt)."""
        model, run = model_from_checkpoint(load_checkpoint(path))
        return cls(name, model, run, fast)

    def canvas(self, step_mm: float) -> tuple[int, int] | None:
        """(H', W') map pixels of the model's input canvas on a ``step_mm`` grid, or None."""
        return input_canvas(self.canvas_mm, step_mm)

    def predict(self, x: np.ndarray, *, eval_mode: bool = False) -> np.ndarray:
        """Class ids: (B,) int64 per image, or (B, h, w) int64 per pixel, background where the
        input is 0 (``eval_mode``: with the unprepared model)."""
        if len(x) == 0:
            return np.zeros((0, *(() if self.task == "classify" else self.size)), np.int64)
        net = self.model if eval_mode else self.net
        pred = logits_of(net, torch.from_numpy(x), BATCH).argmax(1).numpy()
        return pred if self.task == "classify" else unpressed_as_background(pred, x)


def fast_path_agreement(frames: Frames, models: Sequence[Predictor], n: int = 256) -> dict:
    """{model: share of predictions (images or pixels) of the prepared network equal to the
    eval-mode model's} on the first ``n`` regenerated test images of its task."""
    out = {}
    for m in models:
        rows = (frames.classify if m.task == "classify" else frames.segment)[:n]
        x = net_inputs(
            frames.tmap.image(frames.pressure_pa[rows]),
            m.size,
            m.task,
            m.canvas(frames.tmap.step_mm),
        )
        out[m.name] = float((m.predict(x) == m.predict(x, eval_mode=True)).mean())
    return out


@dataclass
class Outputs:
    """Predictions of rows run through one map: ``clf[name]`` (n_clf,), ``seg[name]``
    (n_seg, h, w), and the segmentation rows' images ``seg_images`` (n_seg, H, W) uint8."""

    clf: dict[str, np.ndarray]
    seg: dict[str, np.ndarray]
    seg_images: np.ndarray


def _predict_all(
    images: np.ndarray, models: Sequence[Predictor], step_mm: float
) -> dict[str, np.ndarray]:
    """Every model's predictions for images (B, H, W) uint8 on a ``step_mm`` grid; inputs made
    once per size, task and canvas."""
    out, inputs = {}, {}
    for m in models:
        key = (m.size, m.task, m.canvas_mm)
        if key not in inputs:
            inputs[key] = net_inputs(images, m.size, m.task, m.canvas(step_mm))
        out[m.name] = m.predict(inputs[key])
    return out


def run_rows(
    tmap, p: np.ndarray, is_clf: np.ndarray, is_seg: np.ndarray, models: Sequence[Predictor]
) -> Outputs:
    """Image frames p (B, N) Pa through ``tmap`` and run the classifiers on rows ``is_clf``
    (B,) bool and the segmenters on rows ``is_seg`` (B,) bool, ``CHUNK`` frames at a time."""
    clfs = [m for m in models if m.task == "classify"]
    segs = [m for m in models if m.task == "segment"]
    parts: list[tuple[dict, dict, np.ndarray]] = []
    for s in range(0, len(p), CHUNK):
        images = tmap.image(p[s : s + CHUNK])
        c, g = is_clf[s : s + CHUNK], is_seg[s : s + CHUNK]
        parts.append(
            (
                _predict_all(images[c], clfs, tmap.step_mm),
                _predict_all(images[g], segs, tmap.step_mm),
                images[g],
            )
        )
    seg_images = np.concatenate([q[2] for q in parts]) if parts else np.zeros((0, *tmap.shape))
    return Outputs(_join(parts, 0, clfs), _join(parts, 1, segs), seg_images.astype(np.uint8))


def _join(parts: list, i: int, models: Sequence[Predictor]) -> dict[str, np.ndarray]:
    """Concatenate the chunks' predictions of each model (empty arrays when there are none)."""
    empty = np.zeros((0, 1, 1, 1), np.float32)
    return {
        m.name: np.concatenate([q[i][m.name] for q in parts] or [m.predict(empty)]) for m in models
    }


def _masks(frames: Frames) -> tuple[np.ndarray, np.ndarray]:
    is_clf = np.zeros(len(frames.sample_ids), bool)
    is_seg = np.zeros(len(frames.sample_ids), bool)
    is_clf[frames.classify] = True
    is_seg[frames.segment] = True
    return is_clf, is_seg


def _cms(out: Outputs, frames: Frames, models: Sequence[Predictor], truth: np.ndarray) -> dict:
    """Confusion matrices (lists) per model: classification vs is_hand, segmentation vs
    ``truth`` (K, H', W') label images (IGNORE pixels not counted) at each model's size."""
    cms = {}
    for m in models:
        if m.task == "classify":
            target = frames.is_hand[frames.classify]
            cm = M.confusion_matrix(target, out.clf[m.name], 2)
        else:
            target = net_labels(truth, m.size, m.canvas(frames.tmap.step_mm))
            cm = M.confusion_matrix(target, out.seg[m.name], 7, ignore_index=IGNORE)
        cms[m.name] = cm.tolist()
    return cms


def zero_corruption(frames: Frames, models: Sequence[Predictor]) -> tuple[Outputs, dict]:
    """Predictions and confusion matrices on the images regenerated through the dataset's map."""
    is_clf, is_seg = _masks(frames)
    out = run_rows(frames.tmap, frames.pressure_pa, is_clf, is_seg, models)
    return out, _cms(out, frames, models, frames.label_image)


def blind_spot_study(
    frames: Frames,
    models: Sequence[Predictor],
    spots: Sequence[tuple[int, float]],
    n_patterns: int,
    seed: int,
    progress: bool = False,
) -> dict:
    """Test A: for each (N_s, r mm) in ``spots``, ``n_patterns`` random spot patterns.

    Returns {"baseline": {model: cm}, "conditions": [{"n_spots", "radius_mm", "affected":
    [share of rows changed per pattern], "cm": {model: [cm per pattern]}}]}.
    """
    base, base_cms = zero_corruption(frames, models)
    is_clf, is_seg = _masks(frames)
    conditions = []
    bar = tqdm(total=len(spots) * n_patterns, desc="Test A", disable=not progress)
    for n_spots, radius in spots:
        cond = {
            "n_spots": int(n_spots),
            "radius_mm": float(radius),
            "affected": [],
            "cm": {m.name: [] for m in models},
        }
        for k in range(n_patterns):
            rng = stream(seed, KEY_SPOTS, n_spots, round(radius * 1000), k)
            cms, share = _spot_pattern_cms(
                frames,
                models,
                base,
                is_clf,
                is_seg,
                spot_pattern(frames.tmap, n_spots, radius, rng),
            )
            cond["affected"].append(share)
            for name, cm in cms.items():
                cond["cm"][name].append(cm)
            bar.update()
        conditions.append(cond)
    bar.close()
    return {"baseline": base_cms, "conditions": conditions}


def _spot_pattern_cms(frames, models, base: Outputs, is_clf, is_seg, pattern) -> tuple[dict, float]:
    """Confusion matrices of one blind-spot pattern, and the share of rows it changes."""
    blind, blind_px = pattern
    hit = (frames.pressure_pa[:, blind] > 0).any(axis=1)
    rows = np.flatnonzero(hit)
    p = zero_taxels(frames.pressure_pa[rows], blind)
    new = run_rows(frames.tmap, p, is_clf[rows], is_seg[rows], models)
    hit_clf, hit_seg = hit[frames.classify], hit[frames.segment]
    out = Outputs(
        {k: v.copy() for k, v in base.clf.items()},
        {k: v.copy() for k, v in base.seg.items()},
        base.seg_images,
    )
    for name in out.clf:
        out.clf[name][hit_clf] = new.clf[name]
    for name in out.seg:
        out.seg[name][hit_seg] = new.seg[name]
    truth = frames.label_image.copy()
    seg_k = np.flatnonzero(hit_seg)  # positions among the segmentation rows
    seg_at = np.flatnonzero(is_seg[rows])  # the same rows' positions in p
    for k, j, image in zip(seg_k, seg_at, new.seg_images, strict=True):
        truth[k] = label_image(frames.tmap, p[j], frames.taxel_label[rows[j]], image=image)
    truth[:, blind_px] = 0
    return _cms(out, frames, models, truth), float(hit.mean())


def removal_study(
    frames: Frames,
    models: Sequence[Predictor],
    fractions: Sequence[float],
    n_patterns: int,
    seed: int,
    progress: bool = False,
) -> dict:
    """Test B: ``n_patterns`` nested random removals, each at every fraction in ``fractions``
    (0 means the dataset's own map, the same for every pattern), the map rebuilt each time.

    Returns {"conditions": [{"fraction", "n_kept", "discarded_px": [per pattern],
    "hand_px": [per pattern], "cm": {model: [cm per pattern]}}]}.
    """
    is_clf, is_seg = _masks(frames)
    n = frames.tmap.n_taxels
    conds = [
        {
            "fraction": float(f),
            "n_kept": [],
            "discarded_px": [],
            "hand_px": [],
            "cm": {m.name: [] for m in models},
        }
        for f in fractions
    ]
    done: dict[float, tuple] = {}
    bar = tqdm(total=len(fractions) * n_patterns, desc="Test B", disable=not progress)
    for k in range(n_patterns):
        keeps = nested_removal(n, fractions, stream(seed, KEY_REMOVAL, k))
        for cond, keep in zip(conds, keeps, strict=True):
            f = cond["fraction"]
            if f > 0 or f not in done:
                removed = rebuild(frames.tmap, frames.layout, keep, f)
                out = run_rows(removed.tmap, frames.pressure_pa[:, keep], is_clf, is_seg, models)
                truth = warp_labels(frames.label_image, removed)
                done[f] = (
                    len(keep),
                    *discarded_hand_pixels(frames.label_image, removed),
                    _cms(out, frames, models, truth),
                )
            n_kept, lost, total, cms = done[f]
            cond["n_kept"].append(n_kept)
            cond["discarded_px"].append(lost)
            cond["hand_px"].append(total)
            for name, cm in cms.items():
                cond["cm"][name].append(cm)
            bar.update()
    bar.close()
    return {"conditions": conds}


def scores_pct(cm: list, task: str) -> dict[str, float]:
    """Scores of one confusion matrix in %: accuracy, or the four segmentation scores."""
    s = M.segmentation_scores(cm) if task == "segment" else {"accuracy": M.accuracy(cm)}
    return {k: 100.0 * v for k, v in s.items()}


def spread(values: Sequence[float]) -> dict[str, float]:
    """mean, sd (over patterns, ddof 0), min and max of a list of numbers."""
    v = np.asarray(values, dtype=np.float64)
    return {
        "mean": float(v.mean()),
        "sd": float(v.std()),
        "min": float(v.min()),
        "max": float(v.max()),
    }


def summarize(cms: Sequence[list], task: str) -> dict[str, dict[str, float]]:
    """{score: spread over patterns} from per-pattern confusion matrices."""
    per = [scores_pct(cm, task) for cm in cms]
    return {k: spread([s[k] for s in per]) for k in per[0]}
