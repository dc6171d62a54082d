"""fault-aware: faulty training copies, the augmented data, and the experiment end to end."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
import typer
from matplotlib.image import imread
from typer.testing import CliRunner

from experiments.cli import register
from experiments.fault_aware import FaultAwareScale, fault_aware_model, run_fault_aware
from experiments.faults import augmented_data, faulty_copy, removal_pool
from experiments.frames import KEY_REMOVAL, stream
from experiments.maps import IGNORE, spot_pattern
from experiments.settings import FaultMix, Scale
from learn.train.checkpoint import load_checkpoint
from tactile.dataset import open_dataset
from tactile.errors import ConfigError
from tactile.images.faults import nested_removal, zero_taxels
from tactile.images.labels import label_image

NO_FAULTS = FaultMix(p_blind=0.0, p_dead=0.0, p_drift=0.0, p_removal=0.0)


@pytest.fixture(scope="module")
def hand_frame(tiny_dataset):
    """(map, layout, p (N,) Pa, taxel labels (N,)) of the first hand sample."""
    ds = open_dataset(tiny_dataset)
    i = int(np.flatnonzero(ds.is_hand[:])[0])
    p = ds.pressure_from_raw(ds.raw[i])
    return ds.map, ds.layout, p, ds.taxel_label[i]


def test_no_faults_gives_the_clean_images(hand_frame):
    tmap, _, p, labels = hand_frame
    image, truth = faulty_copy(p, labels, tmap, None, [], NO_FAULTS, np.random.default_rng(0))
    assert np.array_equal(image, tmap.image(p))
    assert np.array_equal(truth, tmap.label_image(p, labels))


def test_blind_spot_copy_is_the_drawn_corruption(hand_frame):
    tmap, _, p, labels = hand_frame
    mix = FaultMix(
        p_blind=1.0, p_dead=0.0, p_drift=0.0, p_removal=0.0, radius_mm=(15.0, 15.0), n_spots=(3, 3)
    )
    image, truth = faulty_copy(p, labels, tmap, None, [], mix, np.random.default_rng(4))
    replay = np.random.default_rng(4)
    replay.random(), replay.integers(3, 4), replay.uniform(15.0, 15.0)
    blind, pixels = spot_pattern(tmap, 3, 15.0, replay)
    faulty = zero_taxels(p, blind)
    assert np.array_equal(image, tmap.image(faulty))
    assert not truth[pixels].any()
    expected = label_image(tmap, faulty, labels)
    assert np.array_equal(truth[~pixels], expected[~pixels])


def test_removal_copy_is_imaged_through_a_pool_map(hand_frame):
    tmap, layout, p, labels = hand_frame
    mix = FaultMix(
        p_blind=0.0, p_dead=0.0, p_drift=0.0, p_removal=1.0, fractions=(0.3, 0.6), pool_patterns=1
    )
    pool = removal_pool(tmap, layout, mix, seed=0)
    assert [len(m.keep) for m in pool] == [
        tmap.n_taxels - round(f * tmap.n_taxels) for f in (0.3, 0.6)
    ]
    image, truth = faulty_copy(p, labels, tmap, None, pool, mix, np.random.default_rng(1))
    shapes = {m.tmap.shape for m in pool}
    assert image.shape in shapes and truth.shape == image.shape
    assert IGNORE not in truth and truth.max() <= 6 and truth.any()
    evaluated = nested_removal(tmap.n_taxels, (0.3, 0.6), stream(0, KEY_REMOVAL, 0))
    assert not any(np.array_equal(e, m.keep) for e, m in zip(evaluated, pool, strict=True))


def test_fault_mix_rejects_bad_probabilities():
    with pytest.raises(ConfigError, match="probabilities"):
        FaultMix(p_blind=1.5)


def test_augmented_data_adds_seeded_faulty_copies(tiny_dataset, tiny_run):
    run = tiny_run("handsnet")
    mix = FaultMix(p_blind=1.0, p_removal=0.5, fractions=(0.5,), pool_patterns=1)
    a = augmented_data(tiny_dataset, run, 8, 2, mix, seed=5, progress=False)
    b = augmented_data(tiny_dataset, run, 8, 2, mix, seed=5, progress=False)
    c = augmented_data(tiny_dataset, run, 8, 2, mix, seed=6, progress=False)
    assert len(a.train.y) == 24 and a.train.x.shape[1:] == (1, *run.model.input_size)
    assert torch.equal(a.train.y[8:16], a.train.y[:8])
    assert torch.equal(a.train.y[16:], a.train.y[:8])
    assert torch.equal(a.train.x, b.train.x)
    assert not torch.equal(a.train.x[8:], c.train.x[8:])
    assert not torch.equal(a.train.x[8:16], a.train.x[:8])
    assert a.description["faulty_copies"] == 2
    n_val = len(a.val.y) // 3
    assert len(a.val.y) == 3 * n_val and torch.equal(a.val.y[n_val : 2 * n_val], a.val.y[:n_val])


def test_fault_aware_end_to_end(tiny_dataset, checkpoints, tmp_path):
    scale = FaultAwareScale(
        Scale(1, None, 4, n_spots=(2,), radii_mm=(20.0,), fractions=(0.0, 0.6)),
        epochs=(1, 1),
        n_train=(8, 8),
        copies=1,
    )
    report = run_fault_aware(
        tiny_dataset,
        tmp_path,
        scale,
        3,
        classifier=checkpoints["handsnet"],
        segmenter=checkpoints["segnet"],
        threads=1,
        progress=False,
    )
    text = report.read_text()
    assert "HandsNet fault-aware" in text and "SegNet fault-aware" in text
    assert "Table 13" in text and "92.67" in text and "Table 14" in text
    for png in ("fa_removal_classification.png", "fa_removal_segmentation.png"):
        img = imread(tmp_path / png)
        assert img[..., :3].std() > 0.02
    res = json.loads((tmp_path / "results.json").read_text())["results"]
    zero = res["test_b"]["conditions"][0]
    assert zero["cm"]["HandsNet"][0] == res["test_a"]["baseline"]["HandsNet"]
    plain = load_checkpoint(checkpoints["handsnet"])["model"]
    tuned = load_checkpoint(tmp_path / "models" / "handsnet_fault_aware" / "best.pt")
    assert any(not torch.equal(plain[k], v) for k, v in tuned["model"].items())
    assert [t["train_images"] for t in res["trained"]] == [16, 16]
    last = tmp_path / "models" / "handsnet_fault_aware" / "last.pt"
    hist = load_checkpoint(last)["history"]  # minutes: the epochs' own, from the run's history
    assert res["trained"][0]["minutes"] == pytest.approx(sum(r["seconds"] for r in hist) / 60)
    assert [t["resumed"] for t in res["trained"]] == [False, False]
    with pytest.raises(ConfigError, match="made otherwise"):  # another recipe, same folder
        fault_aware_model(
            checkpoints["handsnet"],
            tiny_dataset,
            tmp_path / "models" / "handsnet_fault_aware",
            epochs=2,
            n_train=8,
            scale=scale,
            seed=3,
            progress=False,
        )


def test_cli_refuses_bad_settings_before_any_work(tiny_dataset, tmp_path):
    root = typer.Typer()
    register(root)
    out = tmp_path / "o"
    args = ["experiment", "fault-aware", str(tiny_dataset), "--out", str(out), "--copies", "0"]
    res = CliRunner().invoke(root, args)
    assert res.exit_code == 2 and "--copies 0 is out of range" in res.output, res.output
    assert not out.exists()
