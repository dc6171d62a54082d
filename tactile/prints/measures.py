"""What a set of prints looks like: per-sample statistics of a dataset, and their spreads.

    prints = read_prints(open_dataset("out/forearm"))    # one pass over the samples
    prints.active[prints.kind == "hand"]                 # active taxels of every hand print
    mean, low, high = bootstrap_mean(prints.force_n[prints.kind == "hand"], seed=0)

`read_prints` computes, for every sample of a dataset (synthetic or an ingested recording):
the taxels above the dataset's active threshold, the contact area and separate blobs of the
tactile image (after the paper's morphology) and of its grey levels before it, the hand parts a
hand presses, each part's pixels, active taxels and summed pressure, the press force, the
contactor kind and the action, and who pressed (subject, hand side, sex and hand length, from the
contactor's description). A bootstrap over samples gives the 95 % spread of a mean or of a share
of sums, so two datasets (or two simulation settings of one seed) can be compared figure by
figure.
"""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from tqdm import tqdm

from tactile.images.labels import N_CLASSES, label_image
from tactile.images.raster import grey_levels

CHUNK = 256  # samples read per slice of the HDF5 file
EIGHT_NEIGHBOURS = np.ones((3, 3), dtype=bool)  # blobs: pixels touching at an edge or a corner
MAX_DRAWS = 4_000_000  # bootstrap indices drawn at once (32 MB), whatever the sample count


@dataclass(frozen=True)
class Prints:
    """Per-sample statistics of S samples (arrays of length S; NaN where a field is absent).

    kind : (S,) str — "hand", "object", "body" (the contactor's kind), or "non_hand" for an
        ingested recording's non-hand class. action : (S,) str — the interaction ("" unknown).
    active : (S,) int, taxels whose pressure exceeds ``threshold_pa``. area_mm2 : (S,) float,
        pixels of the tactile image above 0 times the pixel area, mm². blobs, blobs_grey : (S,)
        int, 8-connected blobs of the tactile image, and of its grey levels before the
        morphology. parts : (S,) int, hand parts (1..6) among the active taxels (0 without
        labels). part_pixels : (S, 7) int, label-image pixels per class. part_pressure_pa :
        (S, 7) float, summed taxel pressure per class, Pa. part_active : (S, 7) int, active
        taxels per class. force_n : (S,) float, N. subject, side, sex : (S,) str, the hand's
        subject id, "right"/"left" and "male"/"female" ("" unknown). hand_length_m : (S,)
        float, m. fields : the dataset's fields (what a figure needs may be missing).
    """

    kind: np.ndarray
    action: np.ndarray
    active: np.ndarray
    area_mm2: np.ndarray
    blobs: np.ndarray
    blobs_grey: np.ndarray
    parts: np.ndarray
    part_pixels: np.ndarray
    part_pressure_pa: np.ndarray
    part_active: np.ndarray
    force_n: np.ndarray
    subject: np.ndarray
    side: np.ndarray
    sex: np.ndarray
    hand_length_m: np.ndarray
    threshold_pa: float
    has_labels: bool
    fields: tuple[str, ...] = ()
    actions: tuple[str, ...] = ()  # the dataset's action names, in their index order

    def __len__(self) -> int:
        return len(self.kind)


def contactor_columns(contactors, is_hand) -> dict[str, np.ndarray]:
    """Columns of the samples' JSON contactor descriptions: kind ("hand" / "non_hand" from
    ``is_hand`` when absent), subject, side, sex (str, "" unknown), hand_length_m (float, NaN).
    A sample of several contacts (a JSON list) is described by its first hand, else its first
    contact, as its ``action`` and ``subject_id`` are."""
    kinds = np.where(np.asarray(is_hand) > 0, "hand", "non_hand").astype(object)
    n = len(kinds)
    cols = {k: np.full(n, "", dtype=object) for k in ("subject", "side", "sex")}
    length = np.full(n, np.nan)
    for i, text in enumerate([] if contactors is None else contactors):
        try:
            desc = json.loads(text.decode() if isinstance(text, bytes) else text)
        except (ValueError, AttributeError):
            continue
        if isinstance(desc, list) and desc:  # several contacts: the lead, as the sample's
            desc = next((d for d in desc if d.get("kind") == "hand"), desc[0])  # action, person
        if not isinstance(desc, dict):
            continue
        kinds[i] = str(desc.get("kind", kinds[i]))
        cols["subject"][i] = str(desc.get("subject", ""))
        cols["side"][i] = (
            str(desc.get("type", "")).removesuffix("_hand") if "subject" in desc else ""
        )
        cols["sex"][i] = str(desc.get("sex", ""))
        length[i] = float(desc.get("length_m", np.nan))
    return {"kind": kinds.astype(str), "hand_length_m": length} | {
        k: v.astype(str) for k, v in cols.items()
    }


def sample_kinds(contactors: np.ndarray | None, is_hand: np.ndarray) -> np.ndarray:
    """(S,) str: each sample's contactor kind from its JSON description, else hand / non_hand."""
    return contactor_columns(contactors, is_hand)["kind"]


def action_names(ds, action: np.ndarray | None) -> np.ndarray:
    """(S,) str: the action of each sample by the dataset's ``actions`` attribute ("" unknown)."""
    if action is None:
        return np.full(len(ds), "", dtype=object).astype(str)
    names = _action_list(ds)
    out = [names[a] if 0 <= a < len(names) else "" for a in np.asarray(action).tolist()]
    return np.asarray(out, dtype=str)


def _action_list(ds) -> list[str]:
    names = ds.attrs.get("actions")
    return [str(a) for a in names] if isinstance(names, list) else []


def blob_count(mask: np.ndarray) -> int:
    """Number of 8-connected components of a boolean image."""
    return int(ndimage.label(mask, structure=EIGHT_NEIGHBOURS)[1])


def read_prints(ds, progress: bool = False) -> Prints:
    """The statistics of every sample of ``ds`` (a `tactile.dataset.DatasetReader`); a progress
    bar (samples) on stderr with ``progress``."""
    n, tmap, fields = len(ds), ds.map, set(ds.fields)
    labels = "taxel_label" in fields
    thr = ds.active_threshold_pa
    out = {
        "active": np.zeros(n, np.int64),
        "area_mm2": np.zeros(n),
        "blobs": np.zeros(n, np.int64),
        "blobs_grey": np.zeros(n, np.int64),
        "parts": np.zeros(n, np.int64),
        "part_pixels": np.zeros((n, N_CLASSES), np.int64),
        "part_pressure_pa": np.zeros((n, N_CLASSES)),
        "part_active": np.zeros((n, N_CLASSES), np.int64),
    }
    with tqdm(total=n, unit="sample", disable=not progress, dynamic_ncols=True) as bar:
        for start in range(0, n, CHUNK):
            rows = slice(start, min(start + CHUNK, n))
            _read_chunk(ds, rows, tmap, thr, labels, out)
            bar.update(rows.stop - rows.start)
    read = lambda name: ds[name][:] if name in fields else None  # noqa: E731
    force = read("force_n")
    who = contactor_columns(read("contactor"), read("is_hand") if "is_hand" in fields else [0] * n)
    return Prints(
        action=action_names(ds, read("action")),
        force_n=np.full(n, np.nan) if force is None else force.astype(float),
        threshold_pa=thr,
        has_labels=labels,
        fields=tuple(ds.fields),
        actions=tuple(_action_list(ds)),
        **who,
        **out,
    )


def _read_chunk(ds, rows: slice, tmap, thr: float, labels: bool, out: dict) -> None:
    fields = set(ds.fields)
    pressure = ds["pressure_pa"][rows].astype(np.float64)
    images = ds["image"][rows]
    times = ds["time_s"][rows] if "time_s" in fields else None
    sensed = ds.pressure_from_raw(ds["raw"][rows], times)
    shape = pressure.shape
    lab = ds["taxel_label"][rows].astype(np.int64) if labels else np.zeros(shape, np.int64)
    classes = ds["label_image"][rows] if "label_image" in fields else None
    active = pressure > thr
    for j, i in enumerate(range(rows.start, rows.stop)):
        out["active"][i] = int(active[j].sum())
        out["area_mm2"][i] = float((images[j] > 0).sum()) * tmap.step_mm**2
        out["blobs"][i] = blob_count(images[j] > 0)
        grey = grey_levels(tmap.interpolate(sensed[j]), sensed[j].max())
        out["blobs_grey"][i] = blob_count(grey > 0)
        out["parts"][i] = int((np.unique(lab[j][active[j]]) > 0).sum())
        out["part_pressure_pa"][i] = np.bincount(lab[j], weights=pressure[j], minlength=N_CLASSES)
        out["part_active"][i] = np.bincount(lab[j][active[j]], minlength=N_CLASSES)
        if classes is not None:
            out["part_pixels"][i] = np.bincount(classes[j].ravel(), minlength=N_CLASSES)
        elif labels and lab[j].any():
            image = label_image(tmap, sensed[j], lab[j], image=images[j])
            out["part_pixels"][i] = np.bincount(image.ravel(), minlength=N_CLASSES)


def bootstrap_mean(
    values: np.ndarray, n_boot: int = 2000, seed: int = 0, level: float = 0.95
) -> tuple[float, float, float]:
    """(mean, low, high): the mean of ``values`` (NaN ignored) and the percentile bootstrap's
    ``level`` interval over ``n_boot`` resamples of the samples (seeded); NaN when empty."""
    x = np.asarray(values, dtype=float)
    x = x[np.isfinite(x)]
    if not x.size:
        return (float("nan"),) * 3
    means = _resampled(lambda v: v.mean(axis=1), (x,), n_boot, seed)
    return (float(x.mean()), *_interval(means, level))


def bootstrap_share(
    numerator: np.ndarray,
    denominator: np.ndarray,
    n_boot: int = 2000,
    seed: int = 0,
    level: float = 0.95,
) -> tuple[float, float, float]:
    """(share, low, high): summed ``numerator`` over summed ``denominator`` ((S,) per sample)
    and the percentile bootstrap's ``level`` interval over resamples of the samples (seeded);
    NaN when the denominator sums to 0."""
    num, den = np.asarray(numerator, float), np.asarray(denominator, float)
    value = share(num, den)
    if not np.isfinite(value):
        return (float("nan"),) * 3
    with np.errstate(invalid="ignore", divide="ignore"):
        shares = _resampled(lambda a, b: a.sum(axis=1) / b.sum(axis=1), (num, den), n_boot, seed)
    return (value, *_interval(shares, level))


def _resampled(statistic, arrays: tuple, n_boot: int, seed: int) -> np.ndarray:
    """(n_boot,) ``statistic`` of resamples (rows of indices drawn with replacement, seeded) of
    the (S,) ``arrays``, drawn in blocks of at most `MAX_DRAWS` indices."""
    n = len(arrays[0])
    rng, block, out = np.random.default_rng(seed), max(1, MAX_DRAWS // n), []
    for start in range(0, n_boot, block):
        idx = rng.integers(0, n, size=(min(block, n_boot - start), n))
        out.append(statistic(*(a[idx] for a in arrays)))
    return np.concatenate(out)


def _interval(values: np.ndarray, level: float) -> tuple[float, float]:
    tail = 100 * (1 - level) / 2
    low, high = np.nanpercentile(values, [tail, 100 - tail])
    return float(low), float(high)


def share(numerator: np.ndarray, denominator: np.ndarray) -> float:
    """Summed numerator over summed denominator (NaN when the denominator sums to 0)."""
    total = float(np.sum(denominator))
    return float(np.sum(numerator)) / total if total > 0 else float("nan")
