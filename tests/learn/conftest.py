"""Fixtures of the learn/ tests: a tiny tactile dataset with a learnable difference, and small
trained checkpoints.

Hands press a palm disc and four finger stripes (parts labelled 2..6); non-hands press one or
two round blobs. Everything is drawn from the flat lattice coordinates of a small cylinder
sector, so hand and non-hand images differ in shape, as in the real problem.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from learn.config import ModelConfig, RunConfig, TrainConfig
from learn.data.load import load_data
from learn.train.loop import fit
from tactile import TactileMap
from tactile.dataset import DatasetWriter
from tactile.synthetic import cylinder_sector_layout

N_HAND, N_OTHER = 24, 24  # samples; 6 subjects and 6 object instances
SIZE = (32, 48)  # network input (h, w) px in the tests
GAIN = 2.0  # counts per Pa


def hand_pressure(flat_mm: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """(p (N,) Pa, labels (N,) 0..6): palm disc + four finger stripes, randomly placed/turned."""
    angle = rng.uniform(-0.3, 0.3)
    rot = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    s, z = ((flat_mm - rng.uniform(-6, 6, 2) - [0, -15]) @ rot).T
    p, labels = np.zeros(len(s)), np.zeros(len(s), np.uint8)
    palm = s**2 + z**2 < 12**2
    p[palm], labels[palm] = 600.0, 6
    for k, offset in enumerate((-13.5, -4.5, 4.5, 13.5)):
        finger = (np.abs(s - offset) < 3.5) & (z > 14) & (z < 44)
        p[finger], labels[finger] = 400.0, 2 + k
    return p * rng.uniform(0.7, 1.3), labels


def blob_pressure(flat_mm: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(N,) Pa: one or two round blobs of radius 4..10 mm."""
    p = np.zeros(len(flat_mm))
    for _ in range(rng.integers(1, 3)):
        centre, radius = rng.uniform([-20, -35], [20, 35]), rng.uniform(4, 10)
        p[np.hypot(*(flat_mm - centre).T) < radius] = rng.uniform(300, 900)
    return p


def make_sample(i: int, tmap: TactileMap, flat_mm: np.ndarray) -> dict:
    """Sample i: hands for i < N_HAND (subject i // 4), blobs after (instance (i - N_HAND) // 4)."""
    rng = np.random.default_rng(np.random.SeedSequence(7, spawn_key=(i,)))
    hand = i < N_HAND
    p, labels = hand_pressure(flat_mm, rng) if hand else (blob_pressure(flat_mm, rng), None)
    labels = np.zeros(len(p), np.uint8) if labels is None else labels
    return {
        "raw": np.round(GAIN * p).astype(np.uint16),
        "pressure_pa": p.astype(np.float32),
        "image": tmap.image(p),
        "taxel_label": labels,
        "label_image": tmap.label_image(p, labels) if hand else np.zeros(tmap.shape, np.uint8),
        "is_hand": np.uint8(hand),
        "subject_id": np.int32(i // 4 if hand else -1),
        "instance_id": np.int32(-1 if hand else (i - N_HAND) // 4),
        "force_n": np.float32(rng.uniform(1.0, 60.0)),  # drawn last: earlier draws unchanged
    }


def as_object(row: dict) -> dict:
    """A hand row recorded as an object touch (label noise): not a hand, no subject, no part
    labels, instance 100 + subject."""
    if not row["is_hand"]:
        return row
    instance = np.int32(100 + row["subject_id"])
    return {
        **row,
        "is_hand": np.uint8(0),
        "subject_id": np.int32(-1),
        "instance_id": instance,
        "taxel_label": np.zeros_like(row["taxel_label"]),
        "label_image": np.zeros_like(row["label_image"]),
    }


def with_contactor(row: dict) -> dict:
    """``row`` with a ``contactor`` JSON as the generator writes it: hands right or left by
    subject, non-hands a ball or a disc by instance."""
    if row["is_hand"]:
        c = {"kind": "hand", "type": ("right_hand", "left_hand")[int(row["subject_id"]) % 2]}
    else:
        c = {"kind": "object", "type": ("ball", "disc")[int(row["instance_id"]) % 2]}
    return {**row, "contactor": json.dumps(c)}


def write_tiny_dataset(
    folder,
    samples: list[int],
    drop: tuple[str, ...] = (),
    hands_as_objects: bool = False,
    split: str | None = None,
    contactors: bool = False,
):
    """Write samples ``samples`` (`make_sample` numbering) of the tiny set to ``folder``,
    without the fields ``drop``, the hands recorded as objects if ``hands_as_objects``, split by
    method ``split`` (None: the default, greedy), with a ``contactor`` JSON per sample if
    ``contactors`` (`with_contactor`); returns the folder."""
    layout, flat_mm = cylinder_sector_layout(width_mm=60, length_mm=90, pitch_mm=5)
    tmap = TactileMap.build(layout)
    config = {"test": "tiny"} if split is None else {"test": "tiny", "split": split}
    writer = DatasetWriter(
        folder,
        config=config,
        part="sector",
        generator_version="t",
        seed=3,
        tmap=tmap,
        layout=layout,
        attrs={"skin_counts_per_pa": GAIN},
    )
    rows = [make_sample(i, tmap, flat_mm) for i in samples]
    rows = [as_object(r) for r in rows] if hands_as_objects else rows
    rows = [with_contactor(r) for r in rows] if contactors else rows
    writer.write_chunk(0, [{k: v for k, v in r.items() if k not in drop} for r in rows])
    writer.merge()
    return folder


@pytest.fixture(scope="session")
def tiny_writer():
    """`write_tiny_dataset(folder, samples, drop=(), hands_as_objects=False)`: a few tiny
    samples, some fields left out, hands perhaps mislabelled as objects."""
    return write_tiny_dataset


@pytest.fixture(scope="session")
def tiny_dataset(tmp_path_factory):
    """Folder of a 48-sample dataset on a 60 × 90 mm sector (8 mm pitch)."""
    folder = tmp_path_factory.mktemp("learn_data") / "tiny"
    return write_tiny_dataset(folder, list(range(N_HAND + N_OTHER)))


def make_run(arch: str = "handsnet", **train: object) -> RunConfig:
    """A fast RunConfig for tests: small input, 1 thread."""
    classes = 2 if arch in ("handsnet", "vgg16") else 7
    width = None if arch == "handsnet" else 0.125
    model = ModelConfig(arch, classes, width=width, input_size=SIZE)
    defaults = {"epochs": 4, "batch_size": 16, "lr": 0.01, "seed": 0}
    loss = {"loss": "weighted_ce", "optimizer": "adam", "lr": 0.002, "batch_size": 8}
    loss = loss if classes == 7 else {}
    return RunConfig(model=model, train=TrainConfig(**{**defaults, **loss, **train}), threads=1)


@pytest.fixture(scope="session")
def tiny_run():
    """The factory ``tiny_run(arch="handsnet", **train_fields) -> RunConfig`` (fast settings)."""
    return make_run


@pytest.fixture(scope="session")
def checkpoints(tiny_dataset, tmp_path_factory):
    """{"handsnet": best.pt, "segnet": best.pt} trained briefly on the tiny dataset."""
    torch.set_num_threads(1)
    out = {}
    for arch, epochs in (("handsnet", 4), ("segnet", 4)):
        run = make_run(arch, epochs=epochs)
        folder = tmp_path_factory.mktemp("runs") / arch
        fit(run, load_data(tiny_dataset, run), folder, progress=False)
        out[arch] = folder / "best.pt"
    return out


def resume_after_edit(run, data, folder, edit):
    """(uninterrupted run, run resumed) of ``run``: trained whole in ``folder/full``, and in
    ``folder/cut`` stopped after epoch 1, its last.pt's config edited in place by
    ``edit(config)``, then resumed with ``run``."""
    from learn.train.checkpoint import load_checkpoint, save_checkpoint

    full = fit(run, data, folder / "full", progress=False)
    fit(run, data, folder / "cut", progress=False, stop_after_epoch=1)
    last = folder / "cut" / "last.pt"
    ckpt = load_checkpoint(last)
    edit(ckpt["config"])
    save_checkpoint(ckpt, last)
    return full, fit(run, data, folder / "cut", resume=True, progress=False)
