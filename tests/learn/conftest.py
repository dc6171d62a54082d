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
from tactile.geometry.synthetic import cylinder_sector_layout
from tactile.images.labels import label_image

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


# ---- press sequences (action recognition) -------------------------------------------------------

ACTIONS = (
    "grasp",
    "grasp_twist_cw",
    "grasp_twist_ccw",
    "push_left",
    "push_right",
    "push_away",
    "pull",
    "free",
)
SEQ_STORED = 14  # frames of the stored sequences (one press is longer than the networks' 12)
SEQ_BASELINE, SEQ_DRIFT = 100.0, 20.0  # counts, counts/s: frames read at the wrong time differ
#: per action: (shift along s, shift along z) mm per frame, turn degrees per frame
SEQ_MOTION = {
    "grasp": (0, 0, 0),
    "grasp_twist_cw": (0, 0, -8),
    "grasp_twist_ccw": (0, 0, 8),
    "push_left": (3, 0, 0),
    "push_right": (-3, 0, 0),
    "push_away": (0, 3, 0),
    "pull": (0, -3, 0),
    "free": (0, 0, 0),
}


def press_axes(flat_mm: np.ndarray, action: str, k: int, rng_offset: np.ndarray):
    """(s, z) mm of every taxel in the axes of frame k's bar (z its long axis), moved and
    turned by ``SEQ_MOTION`` each frame from its start ``rng_offset`` (mm)."""
    ds, dz, turn = SEQ_MOTION[action]
    angle = np.deg2rad(30 + turn * k)
    rot = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    return ((flat_mm - rng_offset - [ds * k, dz * k]) @ rot).T


def press_frame(flat_mm: np.ndarray, action: str, k: int, rng_offset: np.ndarray) -> np.ndarray:
    """(N,) Pa of frame k of a press: a 14 x 30 mm bar (a 6 mm disc for "free"), `press_axes`."""
    s, z = press_axes(flat_mm, action, k, rng_offset)
    inside = np.hypot(s, z) < 6 if action == "free" else (np.abs(s) < 7) & (np.abs(z) < 15)
    return np.where(inside, 500.0 + 40.0 * k, 0.0)


def press_labels(flat_mm: np.ndarray, action: str, k: int, rng_offset: np.ndarray) -> np.ndarray:
    """(N,) class ids of frame k's pressed taxels: the bar's half at z < 0 the palm, the other
    half the index finger (the hand's axis: +z)."""
    pressed = press_frame(flat_mm, action, k, rng_offset) > 0
    z = press_axes(flat_mm, action, k, rng_offset)[1]
    return np.where(pressed, np.where(z < 0, 6, 2), 0).astype(np.uint8)


def sequence_sample(i: int, tmap: TactileMap, flat_mm: np.ndarray) -> dict:
    """Sample i of the tiny sequence set: hands (i < 32) press action i % 8 for 5-7 frames
    (sample 3: 13), subject i // 4, right or left hand by subject; then 4 objects (no action)."""
    rng = np.random.default_rng(np.random.SeedSequence(11, spawn_key=(i,)))
    hand = i < 32
    action = ACTIONS[i % 8] if hand else "grasp"
    n = 13 if i == 3 else int(rng.integers(5, 8))
    start = rng.uniform(-8, 8, 2)
    t_s = 0.1 * (np.arange(SEQ_STORED) + 1)
    p = np.stack([press_frame(flat_mm, action, k, start) for k in range(n)])
    raw = np.zeros((SEQ_STORED, len(flat_mm)), np.uint16)
    raw[:n] = np.round(SEQ_BASELINE + SEQ_DRIFT * t_s[:n, None] + GAIN * p)
    side = ("right_hand", "left_hand")[(i // 4) % 2]
    contactor = {"kind": "hand", "type": side} if hand else {"kind": "object", "type": "ball"}
    labels = press_labels(flat_mm, action, n - 1, start) if hand else np.zeros(len(p[-1]), int)
    return {
        "raw": raw[n - 1],
        "pressure_pa": p[-1].astype(np.float32),
        "image": tmap.image(p[-1]),
        "label_image": label_image(tmap, p[-1], labels),
        "is_hand": np.uint8(hand),
        "action": np.int8(ACTIONS.index(action) if hand else -1),
        "subject_id": np.int32(i // 4 if hand else -1),
        "instance_id": np.int32(-1 if hand else i - 32),
        "contactor": json.dumps(contactor),
        "time_s": np.float32(t_s[n - 1]),
        "seq_raw": raw,
        "seq_length": np.int16(n),
        "seq_phase_s": np.float32([0.1, 0.25, 0.45, 0.1 * n]),
    }


def write_tiny_sequences(folder, n: int = 36):
    """The tiny sequence set (`sequence_sample` 0..n-1) in ``folder``; returns the folder."""
    layout, flat_mm = cylinder_sector_layout(width_mm=60, length_mm=90, pitch_mm=5)
    tmap = TactileMap.build(layout)
    attrs = {
        "actions": list(ACTIONS),
        "skin_counts_per_pa": GAIN,
        "skin_baseline_counts": SEQ_BASELINE,
        "skin_drift_counts_per_s": SEQ_DRIFT,
        "skin_noise_floor_counts": 1.0,
    }
    writer = DatasetWriter(
        folder,
        config={"test": "tiny sequences"},
        part="sector",
        generator_version="t",
        seed=5,
        tmap=tmap,
        layout=layout,
        seq_len=SEQ_STORED,
        attrs=attrs,
    )
    writer.write_chunk(0, [sequence_sample(i, tmap, flat_mm) for i in range(n)])
    writer.merge()
    return folder


@pytest.fixture(scope="session")
def tiny_sequences(tmp_path_factory):
    """Folder of a 36-sample dataset with press sequences: 32 hand presses (8 subjects, every
    action 4 times), 4 object touches."""
    return write_tiny_sequences(tmp_path_factory.mktemp("learn_sequences") / "tiny")
