"""Test A (blind spots) and Test B (taxels removed) for any number of trained networks at once.

    a = blind_spot_study(frames, models, [(1, 10.0), (4, 40.0)], n_patterns=10, seed=0)
    b = removal_study(frames, models, [0.1, 0.3, 0.6], n_patterns=10, seed=0)

Every pattern regenerates the images of the rows it changes through the corrupted map and runs
every network (``experiments.networks.Predictor``) on them; the images are made once per
pattern and shared by all networks. Under blind spots a frame none of whose pressed taxels is
blind gives the very same image, so only the affected rows are run again (the others keep the
zero-corruption prediction). Each pattern yields one confusion matrix per network, pooled over
the rows; scores are computed per pattern and summarised over patterns.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from tqdm.auto import tqdm

from experiments.frames import CHUNK, KEY_REMOVAL, KEY_SPOTS, Frames, net_inputs, stream
from experiments.maps import IGNORE, discarded_hand_pixels, rebuild, spot_pattern, warp_labels
from learn import metrics as M
from learn.inputs import net_labels
from tactile.images.faults import nested_removal, zero_taxels
from tactile.images.labels import label_image


def run_rows(tmap, p: np.ndarray, is_clf: np.ndarray, is_seg: np.ndarray, models):
    """Image frames p (B, N) Pa through ``tmap`` and run the classifiers on rows ``is_clf``
    (B,) bool and the segmenters on rows ``is_seg`` (B,) bool, ``CHUNK`` frames at a time.

    Returns ({model: predictions, (n_clf,) or (n_seg, h, w)}, the segmented rows' images
    (n_seg, H, W) uint8); network inputs are made once per size, task and canvas.
    """
    preds, seg_images = {m.name: [] for m in models}, [np.zeros((0, *tmap.shape), np.uint8)]
    for s in range(0, len(p), CHUNK):
        images = tmap.image(p[s : s + CHUNK])
        rows = {"classify": is_clf[s : s + CHUNK], "segment": is_seg[s : s + CHUNK]}
        inputs = {}
        for m in models:
            key = (m.size, m.task, m.canvas_mm)
            if key not in inputs:
                canvas = m.canvas(tmap.step_mm)
                inputs[key] = net_inputs(images[rows[m.task]], m.size, m.task, canvas)
            preds[m.name].append(m.predict(inputs[key]))
        seg_images.append(images[rows["segment"]])
    empty = np.zeros((0, 1, 1, 1), np.float32)
    preds = {m.name: np.concatenate(preds[m.name] or [m.predict(empty)]) for m in models}
    return preds, np.concatenate(seg_images)


def _masks(frames: Frames) -> tuple[np.ndarray, np.ndarray]:
    """(is_clf, is_seg): (S,) bool, the rows classified and the rows segmented."""
    is_clf, is_seg = np.zeros((2, len(frames.sample_ids)), bool)
    is_clf[frames.classify], is_seg[frames.segment] = True, True
    return is_clf, is_seg


def _cms(preds: dict, frames: Frames, models: Sequence, truth: np.ndarray) -> dict:
    """Confusion matrices (lists) per model: classification against is_hand, segmentation
    against ``truth`` (K, H', W') label images (IGNORE pixels not counted) at the model's size."""
    cms = {}
    for m in models:
        if m.task == "classify":
            cm = M.confusion_matrix(frames.is_hand[frames.classify], preds[m.name], 2)
        else:
            target = net_labels(truth, m.size, m.canvas(frames.tmap.step_mm)).astype(np.int64)
            cm = M.confusion_matrix(target, preds[m.name], 7, ignore_index=IGNORE)
        cms[m.name] = cm.tolist()
    return cms


def zero_corruption(frames: Frames, models: Sequence) -> tuple[dict, dict]:
    """Predictions and confusion matrices on the images regenerated through the dataset's map."""
    preds = run_rows(frames.tmap, frames.pressure_pa, *_masks(frames), models)[0]
    return preds, _cms(preds, frames, models, frames.label_image)


def blind_spot_study(
    frames: Frames, models: Sequence, spots, n_patterns: int, seed: int, progress: bool = False
) -> dict:
    """Test A: for each (N_s, r mm) in ``spots``, ``n_patterns`` random spot patterns.

    Returns {"baseline": {model: cm}, "conditions": [{"n_spots", "radius_mm", "affected":
    [share of rows changed per pattern], "cm": {model: [cm per pattern]}}]}.
    """
    base, base_cms = zero_corruption(frames, models)
    conditions = []
    bar = tqdm(total=len(spots) * n_patterns, desc="Test A", disable=not progress)
    for n_spots, radius in spots:
        cond = {"n_spots": int(n_spots), "radius_mm": float(radius), "affected": []}
        cond["cm"] = {m.name: [] for m in models}
        for k in range(n_patterns):
            rng = stream(seed, KEY_SPOTS, n_spots, round(radius * 1000), k)
            pattern = spot_pattern(frames.tmap, n_spots, radius, rng)
            cms, share = _spot_pattern_cms(frames, models, base, pattern)
            cond["affected"].append(share)
            for name, cm in cms.items():
                cond["cm"][name].append(cm)
            bar.update()
        conditions.append(cond)
    bar.close()
    return {"baseline": base_cms, "conditions": conditions}


def _spot_pattern_cms(frames: Frames, models, base: dict, pattern) -> tuple[dict, float]:
    """Confusion matrices of one blind-spot pattern, and the share of rows it changes;
    ``base``: the zero-corruption predictions."""
    blind, blind_px = pattern
    is_clf, is_seg = _masks(frames)
    hit = (frames.pressure_pa[:, blind] > 0).any(axis=1)
    rows = np.flatnonzero(hit)
    p = zero_taxels(frames.pressure_pa[rows], blind)
    new, seg_images = run_rows(frames.tmap, p, is_clf[rows], is_seg[rows], models)
    hits = {"classify": hit[frames.classify], "segment": hit[frames.segment]}
    preds = {m.name: base[m.name].copy() for m in models}
    for m in models:
        preds[m.name][hits[m.task]] = new[m.name]
    truth = frames.label_image.copy()
    seg_k = np.flatnonzero(hits["segment"])  # positions among the segmentation rows
    seg_at = np.flatnonzero(is_seg[rows])  # the same rows' positions in p
    for k, j, image in zip(seg_k, seg_at, seg_images, strict=True):
        truth[k] = label_image(frames.tmap, p[j], frames.taxel_label[rows[j]], image=image)
    truth[:, blind_px] = 0
    return _cms(preds, frames, models, truth), float(hit.mean())


def removal_study(
    frames: Frames, models: Sequence, fractions, n_patterns: int, seed: int, progress=False
) -> dict:
    """Test B: ``n_patterns`` nested random removals, each at every share in ``fractions``
    (0 means the dataset's own map, the same for every pattern), the map rebuilt each time.

    Returns {"conditions": [{"fraction", "n_kept": [per pattern], "discarded_px": [...],
    "hand_px": [...], "cm": {model: [cm per pattern]}}]}.
    """
    is_clf, is_seg = _masks(frames)
    keys = ("n_kept", "discarded_px", "hand_px")
    conds = [{"fraction": float(f), **{k: [] for k in keys}} for f in fractions]
    for cond in conds:
        cond["cm"] = {m.name: [] for m in models}
    done: dict[float, tuple] = {}
    bar = tqdm(total=len(fractions) * n_patterns, desc="Test B", disable=not progress)
    for k in range(n_patterns):
        keeps = nested_removal(frames.tmap.n_taxels, fractions, stream(seed, KEY_REMOVAL, k))
        for cond, keep in zip(conds, keeps, strict=True):
            f = cond["fraction"]
            if f > 0 or f not in done:
                removed = rebuild(frames.tmap, frames.layout, keep, f)
                out = run_rows(removed.tmap, frames.pressure_pa[:, keep], is_clf, is_seg, models)[0]
                truth = warp_labels(frames.label_image, removed)
                lost = discarded_hand_pixels(frames.label_image, removed)
                done[f] = (len(keep), *lost, _cms(out, frames, models, truth))
            for key, value in zip(keys, done[f][:3], strict=True):
                cond[key].append(value)
            for name, cm in done[f][3].items():
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
    return {"mean": v.mean(), "sd": v.std(), "min": v.min(), "max": v.max()}


def summarize(cms: Sequence[list], task: str) -> dict[str, dict[str, float]]:
    """{score: spread over patterns} from per-pattern confusion matrices."""
    per = [scores_pct(cm, task) for cm in cms]
    return {k: spread([s[k] for s in per]) for k in per[0]}
