"""TorchTactileDataset: shapes, flips, faults against tactile.images.faults, DataLoader workers."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from torch.utils.data import DataLoader

from learn.data.dataset import FaultSpec, TorchTactileDataset
from tactile import TactileMap, TaxelLayout, resize_image, resize_labels
from tactile.dataset import DatasetWriter, open_dataset
from tactile.errors import ConfigError, DataError
from tactile.geometry.synthetic import cylinder_sector_layout
from tactile.images.faults import (
    blind_spots,
    dead_modules,
    gain_drift,
    nested_removal,
    stuck_at,
    zero_taxels,
)

N_SAMPLES = 20
BASELINE, GAIN = 1000.0, 2.0  # counts, counts/Pa


@pytest.fixture(scope="module")
def path(tmp_path_factory):
    """20 samples (hands of 5 subjects, non-hands of 5 instances) on a layout with modules."""
    base, _ = cylinder_sector_layout(width_mm=60, length_mm=90, pitch_mm=8)
    layout = TaxelLayout(
        base.positions_m, base.normals, module_ids=np.arange(base.n_taxels) // 8, name="sector"
    )
    tmap = TactileMap.build(layout)
    rng = np.random.default_rng(5)
    samples = []
    for i in range(N_SAMPLES):
        hand = i % 2
        pressed = rng.uniform(size=layout.n_taxels) < 0.5
        p = np.round(rng.uniform(0, 800, layout.n_taxels) * pressed)
        labels = (rng.integers(1, 7, layout.n_taxels) * (p > 0) * hand).astype(np.uint8)
        samples.append(
            {
                "raw": (BASELINE + GAIN * p).astype(np.uint16),
                "pressure_pa": p.astype(np.float32),
                "image": tmap.image(p),
                "taxel_label": labels,
                "label_image": tmap.label_image(p, labels)
                if hand
                else np.zeros(tmap.shape, np.uint8),
                "is_hand": np.uint8(hand),
                "subject_id": np.int32(i // 4 if hand else -1),
                "instance_id": np.int32(-1 if hand else i // 4),
            }
        )
    folder = tmp_path_factory.mktemp("learn") / "ds"
    w = DatasetWriter(
        folder,
        config={},
        part="sector",
        generator_version="t",
        seed=1,
        tmap=tmap,
        layout=layout,
        attrs={"skin_counts_per_pa": GAIN, "skin_baseline_counts": BASELINE},
    )
    w.write_chunk(0, samples)
    w.merge()
    return folder


def test_classify_shapes_dtypes_and_split(path):
    ds = TorchTactileDataset(path, split="train", task="classify")
    test = TorchTactileDataset(path, split="test", task="classify", flips=False)
    reader = open_dataset(path)
    assert len(ds) == 3 * len(reader.splits["train"]) and len(test) == len(reader.splits["test"])
    x, y = ds[4]
    assert x.shape == (1, 68, 100) and x.dtype == torch.float32
    assert 0.0 <= x.min() and x.max() <= 1.0 and x.max() > 0
    assert y.dtype == torch.int64 and y.shape == ()
    i = reader.splits["train"][1]
    assert int(y) == int(reader.is_hand[i])
    want = resize_image(reader.image[i].astype(np.float32) / 255, (68, 100))
    np.testing.assert_allclose(ds[3][0][0].numpy(), want, atol=1e-6)


def test_segment_keeps_hand_samples_only_by_default(path):
    reader = open_dataset(path)
    hands = np.flatnonzero(reader.is_hand[:] == 1)
    assert 0 < len(hands) < N_SAMPLES
    ds = TorchTactileDataset(path, split=None, task="segment", size=None, flips=False)
    np.testing.assert_array_equal(ds.indices, hands)
    every = TorchTactileDataset(path, split=None, task="segment", flips=False, hand_only=False)
    assert len(every) == N_SAMPLES
    hand_cls = TorchTactileDataset(path, split="test", task="classify", flips=False, hand_only=True)
    assert set(reader.is_hand[:][hand_cls.indices]) == {1}


def test_segment_targets_and_true_flips(path):
    ds = TorchTactileDataset(path, split=None, task="segment", size=None, hand_only=False)
    reader = open_dataset(path)
    assert len(ds) == 3 * N_SAMPLES
    for k in (1, 6):  # a hand sample (is_hand = k % 2)
        (x0, y0), (x1, y1), (x2, y2) = ds[3 * k], ds[3 * k + 1], ds[3 * k + 2]
        assert y0.dtype == torch.int64 and y0.shape == reader.map.shape
        np.testing.assert_array_equal(y0.numpy(), reader.label_image[k])
        np.testing.assert_array_equal(x0[0].numpy(), reader.image[k] / np.float32(255))
        np.testing.assert_array_equal(x1.numpy(), x0.numpy()[:, :, ::-1])
        np.testing.assert_array_equal(x2.numpy(), x0.numpy()[:, ::-1, :])
        np.testing.assert_array_equal(y1.numpy(), y0.numpy()[:, ::-1])
        np.testing.assert_array_equal(y2.numpy(), y0.numpy()[::-1, :])
    resized = TorchTactileDataset(path, split=None, task="segment", hand_only=False)
    x, y = resized[7]
    assert y.shape == (68, 100) and set(np.unique(y.numpy())) <= set(range(7))
    x6, x8 = resized[6][0].numpy(), resized[8][0].numpy()  # sample 2: original, vertical flip
    np.testing.assert_allclose(x6[:, :, ::-1], x.numpy(), atol=1e-6)
    np.testing.assert_allclose(x6[:, ::-1, :], x8, atol=1e-6)


def test_segment_inputs_are_zero_exactly_where_labels_cannot_be(path):
    """Segmentation inputs keep the nearest-neighbour support of the image, so every labelled
    pixel is seen pressed and no pixel outside the image's support is; classification inputs
    keep the anti-aliased blur (checked against tactile's resize)."""
    seg = TorchTactileDataset(path, split=None, task="segment", flips=False, hand_only=False)
    clf = TorchTactileDataset(path, split=None, task="classify", flips=False)
    reader = open_dataset(path)
    for k in (1, 3):
        x, y = seg[k]
        support = resize_labels(reader.image[k] > 0, (68, 100))
        np.testing.assert_array_equal(x[0].numpy() > 0, support)
        assert np.all(x[0].numpy()[y.numpy() > 0] > 0)
        blur = resize_image(reader.image[k].astype(np.float32) / 255, (68, 100))
        np.testing.assert_allclose(clf[k][0][0].numpy(), blur, atol=1e-6)
        assert (blur > 0).sum() > (x[0].numpy() > 0).sum()


def clean_pressure(path, i: int) -> np.ndarray:
    reader = open_dataset(path)
    return np.maximum(reader.raw[i].astype(float) - BASELINE, 0) / GAIN


def test_blind_spots_and_dead_modules_zero_the_right_taxels(path):
    spec = FaultSpec(blind_spots=(2, 15.0), dead_modules=3, seed=9)
    ds = TorchTactileDataset(path, split=None, faults=spec, size=None, flips=False)
    reader = open_dataset(path)
    for i in (0, 5):
        rng = np.random.default_rng(np.random.SeedSequence(9, spawn_key=(i,)))
        blind = blind_spots(reader.map, 2, 15.0, rng)
        dead = dead_modules(reader.layout.module_ids, 3, rng)
        want = zero_taxels(zero_taxels(clean_pressure(path, i), blind), dead)
        np.testing.assert_array_equal(ds.pressure(i), want)
        assert blind.any() and dead.any() and (clean_pressure(path, i)[blind | dead] > 0).any()
        np.testing.assert_array_equal(ds[i][0][0].numpy(), reader.map.image(want) / np.float32(255))


def test_stuck_at_then_gain_drift_fixed_draw(path):
    spec = FaultSpec(stuck_fraction=0.1, gain_sigma=0.2, seed=4, per_sample=False)
    ds = TorchTactileDataset(path, split=None, faults=spec, flips=False)
    rng = np.random.default_rng(4)
    p, stuck = stuck_at(clean_pressure(path, 3), 0.1, rng)
    want, _ = gain_drift(p, 0.2, rng)
    np.testing.assert_allclose(ds.pressure(3), want)
    assert stuck.sum() == round(0.1 * len(p))


def test_taxel_removal_rebuilds_the_map(path):
    spec = FaultSpec(removal_fraction=0.3, seed=2)
    ds = TorchTactileDataset(path, split=None, task="segment", faults=spec, size=None, flips=False)
    reader = open_dataset(path)
    keep = nested_removal(reader.layout.n_taxels, [0.3], np.random.default_rng(2))[0]
    sub = TactileMap.build(reader.layout.subset(keep))
    i = int(ds.indices[1])  # the second hand sample (segmentation keeps hands only)
    p = clean_pressure(path, i)[keep]
    x, y = ds[1]
    np.testing.assert_array_equal(x[0].numpy(), sub.image(p) / np.float32(255))
    np.testing.assert_array_equal(y.numpy(), sub.label_image(p, reader.taxel_label[i][keep]))
    assert ds.faulty_map()[1] is ds.faulty_map()[1]  # cached


def test_callable_faults(path):
    ds = TorchTactileDataset(path, split=None, faults=lambda p, rng: p * 0, flips=False)
    assert float(ds[2][0].max()) == 0.0


def test_dataloader_with_two_workers(path):
    ds = TorchTactileDataset(path, split="train", task="segment", size=(34, 50))
    loader = DataLoader(ds, batch_size=8, shuffle=False, num_workers=2)
    xs, ys = zip(*loader, strict=True)
    x, y = torch.cat(xs), torch.cat(ys)
    assert x.shape == (len(ds), 1, 34, 50) and y.shape == (len(ds), 34, 50)
    for j in (0, len(ds) - 1):
        torch.testing.assert_close(x[j], ds[j][0])
        torch.testing.assert_close(y[j], ds[j][1])


def test_bad_arguments(path, tmp_path):
    with pytest.raises(ConfigError, match="unknown task 'detect'; choices: classify, segment"):
        TorchTactileDataset(path, task="detect")
    with pytest.raises(ConfigError, match="unknown split"):
        TorchTactileDataset(path, split="val")
    with pytest.raises(DataError, match="no dataset at"):
        TorchTactileDataset(tmp_path)
    layout, _ = cylinder_sector_layout(width_mm=40, length_mm=60, pitch_mm=8)
    np.save(tmp_path / "f.npy", np.ones((2, layout.n_taxels), dtype=np.int64))
    layout.save(tmp_path / "l.csv")
    from tactile.dataset import ingest_recording

    ingest_recording(tmp_path / "l.csv", tmp_path / "f.npy", tmp_path / "rec")
    with pytest.raises(DataError, match=r"no \['label_image'\] for task 'segment'"):
        TorchTactileDataset(tmp_path / "rec", split=None, task="segment")
