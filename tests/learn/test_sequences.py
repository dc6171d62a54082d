"""The press sequences as network inputs (learn.data.sequences) against a slow reference: each
frame through the dataset's own per-frame readout and image (`images_from_raw` at its time)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from learn.config import ModelConfig, RunConfig, TrainConfig
from learn.data.load import load_data
from learn.data.sequences import FRAMES, SequenceDataset, hand_sides
from learn.inputs import net_input
from tactile.dataset import open_dataset
from tactile.errors import DataError

SIZE = (32, 48)


def reference_item(path, i: int, size) -> tuple[np.ndarray, int]:
    """Sample i's frames the slow way: one `images_from_raw` per frame, read at 0.1 (k + 1) s,
    each resized alone, zeros after the press, at most FRAMES frames."""
    ds = open_dataset(path)
    n = min(int(ds.seq_length[i]), FRAMES)
    x = np.zeros((FRAMES, *size), np.float32)
    for k in range(n):
        image = ds.images_from_raw(ds.seq_raw[i][k], time_s=0.1 * (k + 1))
        x[k] = net_input(image, size, "classify")
    return x, int(ds.action[i])


@pytest.mark.parametrize("split", ["train", "test"])
def test_items_equal_the_per_frame_reference(tiny_sequences, split):
    ds = SequenceDataset(tiny_sequences, split, SIZE)
    raw = open_dataset(tiny_sequences)
    expected = [i for i in raw.splits[split] if raw.action[i] >= 0]
    assert list(ds.indices) == expected and len(ds) == len(expected)
    for j, i in enumerate(ds.indices):
        x, y = ds[j]
        ref_x, ref_y = reference_item(tiny_sequences, int(i), SIZE)
        assert x.shape == (FRAMES, 1, *SIZE) and x.dtype == torch.float32
        np.testing.assert_allclose(x[:, 0].numpy(), ref_x, rtol=0, atol=1e-6)
        assert int(y) == ref_y


def test_a_longer_press_keeps_its_first_frames(tiny_sequences):
    ds = SequenceDataset(tiny_sequences, None, SIZE)
    j = list(ds.indices).index(3)  # sample 3 lasts 13 frames
    assert ds.lengths[j] == FRAMES and int(open_dataset(tiny_sequences).seq_length[3]) == 13
    assert (ds[j][0].flatten(1).amax(1) > 0).all()


def test_frames_at_their_own_time(tiny_sequences):
    """Frames read as if at t = 0 keep the baseline drift (20 counts/s) and light every taxel."""
    ds = open_dataset(tiny_sequences)
    raw = ds.seq_raw[0][4]
    right = ds.images_from_raw(raw, time_s=0.5)
    wrong = ds.images_from_raw(raw, time_s=0.0)
    item = SequenceDataset(tiny_sequences, None, None)[0][0][4, 0].numpy()
    np.testing.assert_allclose(item, right / 255.0, atol=1e-6)
    assert (wrong > 0).mean() > 0.9 > (right > 0).mean()


def test_hand_sides_from_the_contactor(tiny_sequences):
    ds = open_dataset(tiny_sequences)
    sides = hand_sides(ds, np.arange(len(ds)))
    for i, side in enumerate(sides):
        kind = json.loads(ds.contactor[i].decode())["type"]
        assert side == {"right_hand": "right", "left_hand": "left"}.get(kind, "")


def test_load_data_of_an_action_run(tiny_sequences):
    run = RunConfig(
        ModelConfig("action_3d", 8, width=0.25, input_size=SIZE),
        TrainConfig(seed=0),
        val_fraction=0.2,
    )
    data = load_data(tiny_sequences, run, progress=False)
    assert data.train.x.shape[1:] == (FRAMES, 1, *SIZE)
    assert data.class_names[3:5] == ("push_left", "push_right")
    assert data.train.mirror.tolist() == [0, 2, 1, 4, 3, 5, 6, 7]
    ds = open_dataset(tiny_sequences)
    n_hands_train = int((ds.action[:][ds.splits["train"]] >= 0).sum())
    assert len(data.train.y) + len(data.val.y) == n_hands_train


def test_a_dataset_without_sequences_names_the_fix(tiny_dataset):
    with pytest.raises(DataError, match="--keep-sequences"):
        SequenceDataset(tiny_dataset, "train", SIZE)
