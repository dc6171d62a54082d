"""Touch recognised frame by frame inside a robot's loop: a taxel frame to its class, hand parts,
per-taxel labels and per-part summary, with the latency of each answer.

    tmap, layout, to_pa = load_map("data/paper")     # learn.infer.predict: the skin's map
    rec = Recognizer(tmap, load_predictor("runs/handsnet/best.pt"), load_predictor("seg.pt"))
    answer = rec.step(to_pa(raw_counts))   # .class_name, .taxel_labels, .parts, .latency_ms

The answers are `learn.infer.predict.predict_frame`'s: the same tactile image, network inputs
and back-projection, computed by the operators of `learn.infer.frame` on the box the touch
covers, into buffers allocated once per recognizer (one recognizer per stream; not shared
between threads). A frame that presses no taxel gives the classifier's answer to an empty
image, computed once, and no hand part, without running a network.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np
import torch

from learn.data.folder import HAND_NAMES
from learn.infer.fastpath import FastInference, compile_frozen
from learn.infer.frame import Box, ImageOps, InputOps, TaxelVotes
from learn.infer.predict import Predictor
from learn.numerics import flushing
from learn.train.device import bf16_supported
from tactile.errors import ConfigError, DataError
from tactile.images.labels import PartSummary, part_summary
from tactile.images.tactile_map import TactileMap


@dataclass
class Answer:
    """One frame's answer; ``None`` where the network was not given."""

    class_name: str | None = None
    probability: float | None = None  # softmax probability of ``class_name``, 0..1
    segmentation: np.ndarray | None = None  # (h, w) uint8 classes 0..6 at the network's input
    taxel_labels: np.ndarray | None = None  # (N,) uint8 classes 0..6, back-projected
    parts: dict[str, PartSummary] | None = None  # per hand part: taxels pressed, mean Pa
    latency_ms: float = 0.0  # time of `Recognizer.step`, ms

    def as_json(self, labels: bool = True) -> dict:
        """The answer as a JSON object (``labels``: with the per-taxel labels)."""
        out: dict = {}
        if self.class_name is not None:
            out |= {"class": self.class_name, "probability": round(self.probability, 6)}
        if self.parts is not None:
            out["parts"] = {
                name: {"taxels": s.n_taxels, "mean_pa": round(s.mean_pressure, 3)}
                for name, s in self.parts.items()
            }
        if labels and self.taxel_labels is not None:
            out["taxel_labels"] = self.taxel_labels.tolist()
        return out


def compiled(pred: Predictor) -> Predictor:
    """``pred`` with its network compiled by TorchInductor for single frames (the arithmetic of
    its eager path, weights frozen; `learn.infer.fastpath.compile_frozen`); int8 stays eager."""
    if getattr(pred.model, "int8", False):
        return pred
    net = compile_frozen(pred.model, torch.zeros(1, 1, *pred.input_size))
    return dataclasses.replace(pred, model=net)


def bf16_weights(pred: Predictor) -> Predictor:
    """``pred`` (one network on the fast path) with its weights in bfloat16, as the fast path
    stores a classifier's: about twice as fast on CPUs with native bf16, and the decisions of
    near ties change. ConfigError on a CPU without native bf16 or for an ensemble."""
    if not bf16_supported():
        raise ConfigError(
            "--bf16: this CPU has no native bfloat16 (AVX512-BF16 or AMX), where it runs "
            "slower than float32. Fix: run without --bf16"
        )
    if not isinstance(pred.model, FastInference):
        raise ConfigError("--bf16 takes one segmenter checkpoint, not an ensemble or TTA")
    return dataclasses.replace(pred, model=FastInference(pred.model.net, True).eval())


class Recognizer:
    """A tactile map with a classifier, a segmenter or both (`learn.infer.predict.Predictor`),
    answering taxel frames (N,) of pressures, Pa, one at a time. ``threshold_pa``: the per-part
    summary counts the taxels above it, Pa. A class-and-parts network (task "both", given as
    either) answers both in one pass."""

    def __init__(
        self,
        tmap: TactileMap,
        classifier: Predictor | None = None,
        segmenter: Predictor | None = None,
        threshold_pa: float = 0.0,
    ) -> None:
        if classifier is None and segmenter is None:
            raise ConfigError("give a classifier, a segmenter or both")
        one = next((p for p in (classifier, segmenter) if p is not None and p.task == "both"), None)
        if one is not None:
            if {id(p) for p in (classifier, segmenter) if p is not None} != {id(one)}:
                raise ConfigError("a class-and-parts network answers both; give it alone")
            classifier = segmenter = one
        for pred, task, role in (
            (classifier, "classify", "classifier"),
            (segmenter, "segment", "segmenter"),
        ):
            if pred is not None and pred.task not in (task, "both"):
                raise ConfigError(f"the {role} is a '{pred.task}' network; give a '{task}' one")
        if not threshold_pa >= 0:
            raise ConfigError(f"threshold {threshold_pa} Pa: give a pressure >= 0")
        self.tmap, self.classifier, self.segmenter = tmap, classifier, segmenter
        self.threshold_pa = float(threshold_pa)
        self._pix = ImageOps.build(tmap)
        self._image_ext = np.zeros(tmap.shape[0] * tmap.shape[1] + 1, np.uint8)
        self._image = self._image_ext[1:].reshape(tmap.shape)
        self._box: Box | None = None
        ops: dict[tuple, InputOps] = {}
        self._clf = self._seg = self._votes = self._empty = None
        self._one = one is not None
        if self._one:
            self._seg = self._clf = _NetBuffers(one, tmap, ops)
            self._votes = TaxelVotes.build(tmap, self._seg.ops)
            self._empty = self._one_pass(None)[:2]
            return
        if classifier is not None:
            self._clf = _NetBuffers(classifier, tmap, ops)
            self._empty = self._classify(None)  # an empty frame's answer, computed once
        if segmenter is not None:
            self._seg = _NetBuffers(segmenter, tmap, ops)
            self._votes = TaxelVotes.build(tmap, self._seg.ops)

    def check(self, p: np.ndarray) -> np.ndarray:
        """``p`` as (N,) float64, Pa; DataError naming the problem for a frame of the wrong
        length or with a value that is not a finite number."""
        p = np.asarray(p, dtype=np.float64).reshape(-1)
        if len(p) != self.tmap.n_taxels:
            raise DataError(f"a frame of {len(p)} values; the map has {self.tmap.n_taxels} taxels")
        bad = ~np.isfinite(p)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise DataError(f"taxel {i} of the frame is {p[i]}; give finite pressures")
        return p

    @flushing()
    def step(self, p: np.ndarray) -> Answer:
        """The answer to one frame ``p`` (N,) of taxel pressures, Pa."""
        start = time.perf_counter()
        p = self.check(p)
        self._box = self._pix.fill(p, self._image, self._box)
        answer = Answer()
        if self._one:
            k, prob, answer.segmentation, answer.taxel_labels = self._one_pass(self._box)
            answer.class_name, answer.probability = HAND_NAMES[k], prob
            answer.parts = part_summary(answer.taxel_labels, p, threshold=self.threshold_pa)
            answer.latency_ms = 1e3 * (time.perf_counter() - start)
            return answer
        with torch.inference_mode():
            if self._clf is not None:
                k, prob = self._empty if self._box is None else self._classify(self._box)
                names = self.classifier.class_names
                answer.class_name, answer.probability = names[k] if k < len(names) else str(k), prob
            if self._seg is not None:
                answer.segmentation, answer.taxel_labels = self._segment()
                answer.parts = part_summary(answer.taxel_labels, p, threshold=self.threshold_pa)
        answer.latency_ms = 1e3 * (time.perf_counter() - start)
        return answer

    def _one_pass(self, box: Box | None) -> tuple[int, float, np.ndarray, np.ndarray]:
        """(class index, its probability, segmentation (h, w), taxel labels (N,)) of a
        class-and-parts network on the current image (an empty frame: the class only)."""
        buf = self._seg
        if box is None and self._empty is not None:
            blank = np.zeros(buf.resized.shape, np.uint8)
            return (*self._empty, blank, np.zeros(self.tmap.n_taxels, np.uint8))
        buf.ops.resize(self._image, box, buf.resized)
        buf.ops.keep_support(buf.resized, self._image_ext, box, buf.input)
        with torch.inference_mode(), flushing():
            logits, parts = self.segmenter.model(buf.x)
        probs = logits[0].float().softmax(0)
        k = int(probs.argmax())
        labels = parts[0].argmax(0).numpy()
        if box is None:
            return k, float(probs[k]), labels, np.zeros(self.tmap.n_taxels, np.uint8)
        buf.labels_ext[1:] = labels.ravel()
        taxel_labels = self._votes.labels(buf.labels_ext, self._image_ext, box)
        return k, float(probs[k]), (labels * (buf.input > 0)).astype(np.uint8), taxel_labels

    def _classify(self, box: Box | None) -> tuple[int, float]:
        """(class index, its softmax probability) of the classifier on the current image."""
        buf = self._clf
        buf.ops.resize(self._image, box, buf.resized)
        with torch.inference_mode(), flushing():
            probs = self.classifier.model(buf.x)[0].float().softmax(0)
        k = int(probs.argmax())
        return k, float(probs[k])

    def _segment(self) -> tuple[np.ndarray, np.ndarray]:
        """(segmentation (h, w), taxel labels (N,)) of the current image."""
        buf, box = self._seg, self._box
        if box is None:
            return np.zeros(buf.resized.shape, np.uint8), np.zeros(self.tmap.n_taxels, np.uint8)
        if self._clf is not None and self._clf.ops is buf.ops:
            resized = self._clf.resized  # the classifier's, resized for this frame
        else:
            resized = buf.ops.resize(self._image, box, buf.resized)
        buf.ops.keep_support(resized, self._image_ext, box, buf.input)
        labels = self.segmenter.model(buf.x)[0].argmax(0).numpy()
        buf.labels_ext[1:] = labels.ravel()
        taxel_labels = self._votes.labels(buf.labels_ext, self._image_ext, box)
        return (labels * (buf.input > 0)).astype(np.uint8), taxel_labels


class _NetBuffers:
    """One network's operators (shared by networks that see the map alike) and buffers: the
    resized image, the network input (as ``x``, a (1, 1, h, w) tensor on the same memory) and
    its labels after a 0."""

    def __init__(self, pred: Predictor, tmap: TactileMap, ops: dict[tuple, InputOps]) -> None:
        canvas = pred.canvas(tmap.step_mm)
        key = (tuple(pred.input_size), canvas)
        if key not in ops:
            ops[key] = InputOps.build(tmap, pred.input_size, canvas)
        self.ops = ops[key]
        h, w = pred.input_size
        self.resized = np.zeros((h, w), np.float32)
        self.input = self.resized if pred.task == "classify" else np.zeros((h, w), np.float32)
        self.x = torch.from_numpy(self.input)[None, None]
        self.labels_ext = np.zeros(h * w + 1, np.uint8)
