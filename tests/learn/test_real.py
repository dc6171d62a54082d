"""Scores on real box-labelled prints (`learn.evaluate.real`), the box folder as training data
(`learn.data.boxes`) and the fine-tuning experiment (`experiments.real_finetune`), on box
folders written here: the tiny set's hand prints, each part boxed around its pixels, and prints
drawn with known boxes; expected scores counted by hand or by a slow per-pixel loop."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image
from typer.testing import CliRunner

from experiments.real_finetune import FinetunePlan, run_finetune, subset, with_replay
from handskin.cli import app
from learn.data.boxes import BoxFolderDataset
from learn.evaluate.real import evaluate_real, localise
from learn.infer.predict import load_predictor, predict_image
from learn.train.losses import SegmentationLoss, class_weights
from tactile.dataset import open_dataset
from tactile.dataset.boxes import BoxFolder, box_labels
from tactile.errors import ConfigError, DataError
from tactile.images.labels import CLASS_NAMES, IGNORE
from tactile.prints.shapes import boxes_of_labels, part_layout

SIZE = (32, 48)


def write_box_folder(root, prints) -> BoxFolder:
    """A self-describing box folder (data.yaml with our part names) of (image, boxes (K, 5))."""
    (root / "images").mkdir(parents=True)
    (root / "labels").mkdir()
    names = list(CLASS_NAMES[1:])
    for i, (image, boxes) in enumerate(prints):
        Image.fromarray(image).save(root / "images" / f"{i}.png")
        h, w = image.shape
        lines = [
            f"{part - 1} {(c0 + c1) / 2 / w} {(r0 + r1) / 2 / h} {(c1 - c0) / w} {(r1 - r0) / h}"
            for part, r0, r1, c0, c1 in boxes.tolist()
        ]
        (root / "labels" / f"{i}.txt").write_text("\n".join(lines) + "\n")
    (root / "data.yaml").write_text(f"names: {names}\nlabels_from: boxes\n")
    return BoxFolder.open(root)


@pytest.fixture(scope="module")
def real_like(tiny_dataset, tmp_path_factory) -> tuple:
    """Two box folders (train, test) of the tiny set's hand prints, parts boxed tightly."""
    with open_dataset(tiny_dataset) as ds:
        hands = np.flatnonzero(ds.is_hand[:] == 1)
        prints = [
            (np.asarray(ds.image[i]), boxes_of_labels(np.asarray(ds.label_image[i]), ds.image[i]))
            for i in hands
        ]
    root = tmp_path_factory.mktemp("real")
    half = len(prints) // 2
    return (
        root / "train",
        root / "test",
        write_box_folder(root / "train", prints[:half]),
        write_box_folder(root / "test", prints[half:]),
    )


def test_localise_counted_by_hand():
    image = np.zeros((10, 12), np.uint8)
    image[1:5, 1:5] = 100  # 16 px, the thumb box rows 0-6, columns 0-6
    image[6:9, 7:11] = 100  # 12 px, the index box rows 6-9, columns 6-12
    boxes = np.array([[1, 0, 6, 0, 6], [2, 6, 9, 6, 12]])
    prediction = np.zeros_like(image)
    prediction[1:5, 1:5] = 1
    prediction[1:3, 1:5] = 2  # 8 index, 8 thumb in the thumb box: a tie, the smaller id wins
    prediction[6:9, 7:11] = 3  # all middle in the index box
    got = localise(prediction, image, boxes)
    assert [g["majority"] for g in got] == [1, 3] and [g["pixels"] for g in got] == [16, 12]
    # thumb: predicted rows 3-4, columns 1-4 (8 px box) inside the 36 px real box: IoU 8 / 36;
    # index: predicted rows 1-2, columns 1-4, nowhere near the index box: IoU 0
    assert got[0]["iou"] == pytest.approx(8 / 36) and got[1]["iou"] == 0.0


def slow_localisation(seg_path, folder: BoxFolder) -> tuple[int, int, list]:
    """(boxes localised, boxes with pixels, (print, part, majority) of each box with pixels):
    every pixel visited in a Python loop."""
    pred = load_predictor(seg_path)
    right = total = 0
    said = []
    for i in range(len(folder)):
        p = folder[i]
        seg = predict_image(p.image, None, pred).segmentation
        area = [(b[2] - b[1]) * (b[4] - b[3]) for b in p.boxes.tolist()]
        votes = [np.zeros(7, int) for _ in p.boxes]
        for r in range(p.image.shape[0]):
            for c in range(p.image.shape[1]):
                if p.image[r, c] <= 4:
                    continue
                holding = [
                    k
                    for k, b in enumerate(p.boxes.tolist())
                    if b[1] <= r < b[2] and b[3] <= c < b[4]
                ]
                if holding:
                    votes[min(holding, key=lambda k: (area[k], -k))][seg[r, c]] += 1
        for k, b in enumerate(p.boxes.tolist()):
            if votes[k].sum():
                total += 1
                right += int(votes[k].argmax() == b[0])
                said.append((i, b[0], int(votes[k].argmax())))
    return right, total, said


def test_evaluate_real_against_a_slow_reference(real_like, checkpoints, tiny_dataset):
    _, test_path, _, test = real_like
    rows, predictions = evaluate_real(
        test_path, [checkpoints["handsnet"], checkpoints["segnet"]], negatives=tiny_dataset
    )
    clf, seg = rows
    assert clf["labels_from"] == seg["labels_from"] == "boxes"
    said = [
        predict_image(test[i].image, load_predictor(checkpoints["handsnet"])).class_name
        for i in range(len(test))
    ]
    assert clf["n_real"] == len(test) and clf["hand_recall"] == pytest.approx(
        np.mean(np.array(said) == "hand")
    )
    with open_dataset(tiny_dataset) as ds:
        test_idx = np.asarray(ds.splits["test"])
        assert clf["n_non_hand"] == int((ds.is_hand[:][test_idx] == 0).sum())
    right, total, said = slow_localisation(checkpoints["segnet"], test)
    assert seg["boxes"] == total and seg["localised"] == pytest.approx(right / total)
    assert sum(v["boxes"] for v in seg["per_part"].values()) == total
    assert len(predictions) == len(test)
    for part, counts in seg["taken_for"].items():
        k = CLASS_NAMES.index(part)
        assert counts == [sum(1 for _, p, m in said if p == k and m == c) for c in range(7)]
    # by where the fingers point: 45-degree bins from -180, then none
    deg = np.array([part_layout(test[i].boxes)["fingers_deg"] for i, _, _ in said])
    ok = np.array([p == m for _, p, m in said])
    rows_deg = seg["by_direction"]
    assert sum(r["boxes"] for r in rows_deg) == total and rows_deg[-1]["from_deg"] is None
    assert rows_deg[-1]["boxes"] == int(np.isnan(deg).sum())
    for r in rows_deg[:-1]:
        m = (deg >= r["from_deg"]) & (deg < r["to_deg"])
        assert r["boxes"] == int(m.sum())
        if m.any():
            assert r["localised"] == pytest.approx(ok[m].mean())


def test_box_folder_trains_a_segmenter_with_unlabelled_pixels_ignored(real_like):
    train_path, _, train, _ = real_like
    ds = BoxFolderDataset(train_path, None, "segment", SIZE, flips=True)
    assert len(ds) == 3 * len(train)
    x, y = ds[0]
    assert x.shape == (1, *SIZE) and y.shape == SIZE and ((x[0] > 0) == (y > 0)).all()
    image = np.zeros((20, 30), np.uint8)
    image[2:8, 2:8], image[12:18, 20:28] = 200, 100  # the second blob in no box
    labels = torch.from_numpy(box_labels(image, np.array([[6, 0, 10, 0, 10]])).astype(np.int64))
    assert set(labels.unique().tolist()) == {0, 6, IGNORE}
    logits = torch.randn(1, 7, 20, 30)
    masked = labels.clone()[None]
    loss = SegmentationLoss("weighted_ce", class_weights(masked, 7))(logits, masked)
    keep = masked != IGNORE
    plain = torch.nn.functional.cross_entropy(
        logits.permute(0, 2, 3, 1)[keep],
        masked[keep],
        weight=torch.tensor(class_weights(masked, 7)).float(),
    )
    assert loss.item() == pytest.approx(plain.item(), rel=1e-5)
    dice = SegmentationLoss("dice")(logits, masked)
    assert torch.isfinite(dice)


def test_subsets_are_nested_per_draw_and_shared_by_the_starts():
    a, b = subset(342, 10, 0, 0), subset(342, 10, 1, 0)
    assert len(a) == 10 and len(set(a)) == 10 and not np.array_equal(a, b)
    assert np.array_equal(a, subset(342, 10, 0, 0)) and len(subset(342, 342, 0, 0)) == 342


def test_replay_repeats_the_real_prints_to_as_many_as_the_simulated():
    from learn.data.load import TensorData

    real = TensorData(torch.zeros(3, 1, 4, 5), torch.ones(3, 4, 5, dtype=torch.int64))
    sim = TensorData(torch.ones(10, 1, 4, 5), torch.zeros(10, 4, 5, dtype=torch.int64))
    x, y = with_replay(real, sim)
    assert x.shape == (10 + 9, 1, 4, 5) and y.shape == (19, 4, 5)  # 10 // 3 = 3 copies of 3
    assert int((x[:, 0, 0, 0] == 0).sum()) == 9 and bool((y[:10] == 0).all())
    big = TensorData(torch.zeros(12, 1, 4, 5), torch.ones(12, 4, 5, dtype=torch.int64))
    assert len(with_replay(big, sim)[1]) == 22  # more real than simulated: each once
    assert with_replay(real, None)[0] is real.x


def test_finetune_refuses_a_replay_source_before_any_work(real_like, checkpoints, tmp_path):
    train_path, test_path, _, _ = real_like
    plan = FinetunePlan(ks=(2,), draws=(1,), steps=1, threads=1, replay=2)
    out = tmp_path / "ft"
    with pytest.raises(DataError, match="--replay-from"):
        run_finetune(checkpoints["segnet"], train_path, test_path, out, plan, False, train_path)
    with pytest.raises(ConfigError, match="--replay 100000"):
        big = FinetunePlan(ks=(2,), draws=(1,), steps=1, threads=1, replay=100_000)
        run_finetune(checkpoints["segnet"], train_path, test_path, out, big, progress=False)
    with pytest.raises(ConfigError, match=r"--replay-from .* with --replay 0"):
        none = FinetunePlan(ks=(2,), draws=(1,), steps=1, threads=1, replay=0)
        run_finetune(checkpoints["segnet"], train_path, test_path, out, none, False, test_path)
    assert not out.exists()


def test_replay_changes_the_pretrained_runs_only(real_like, checkpoints, tmp_path):
    """With and without replay the random starts are the same bytes, the pretrained ones not;
    results written before replay existed resume as runs without it."""
    train_path, test_path, _, _ = real_like
    rows = {}
    for replay in (0, 3):
        plan = FinetunePlan(ks=(2,), draws=(1,), steps=3, threads=1, replay=replay)
        done = run_finetune(
            checkpoints["segnet"], train_path, test_path, tmp_path / f"r{replay}", plan, False
        )
        rows[replay] = {r["start"]: r for r in done["runs"]}
    assert rows[0]["random"] == rows[3]["random"]
    assert rows[0]["simulation"]["prints"] == rows[3]["simulation"]["prints"]
    assert rows[0]["simulation"] != rows[3]["simulation"]
    results = tmp_path / "r0" / "results.json"
    old = json.loads(results.read_text())
    for field in ("replay_from", "replay_fingerprint"):
        del old["key"][field]
    del old["key"]["plan"]["replay"]
    results.write_text(json.dumps(old))
    plan = FinetunePlan(ks=(2,), draws=(1,), steps=3, threads=1, replay=0)
    again = run_finetune(checkpoints["segnet"], train_path, test_path, tmp_path / "r0", plan, False)
    assert again["runs"] == old["runs"]


def test_finetune_experiment_runs_resumes_and_charts(
    real_like, checkpoints, tiny_dataset, tmp_path
):
    train_path, test_path, train, _ = real_like
    plan = FinetunePlan(ks=(2, len(train)), draws=(2, 1), steps=2, threads=1, replay=3)
    out = tmp_path / "ft"
    done = run_finetune(checkpoints["segnet"], train_path, test_path, out, plan, progress=False)
    assert Path(done["key"]["replay_from"]).resolve() == Path(tiny_dataset).resolve()
    runs = done["runs"]
    assert len(runs) == 2 * (2 + 1)
    for k, draw in ((2, 0), (2, 1), (len(train), 0)):
        mine = [r for r in runs if r["k"] == k and r["draw"] == draw]
        assert {r["start"] for r in mine} == {"simulation", "random"}
        assert mine[0]["prints"] == mine[1]["prints"] and len(mine[0]["prints"]) == k
    assert 0 <= done["zero_shot"]["localised"] <= 1
    text = (out / "report.md").read_text()
    assert "Zero-shot" in text and "| 2 | 2 |" in text and (out / "localisation.png").is_file()
    before = json.loads((out / "results.json").read_text())
    again = run_finetune(checkpoints["segnet"], train_path, test_path, out, plan, progress=False)
    assert again["runs"] == before["runs"]  # resumed: nothing trained twice


def test_evaluate_command_on_a_box_folder(real_like, checkpoints, tiny_dataset, tmp_path):
    _, test_path, _, _ = real_like
    out = tmp_path / "real.md"
    args = ["evaluate", str(test_path), str(checkpoints["handsnet"]), str(checkpoints["segnet"])]
    res = CliRunner().invoke(app, [*args, "--out", str(out), "--negatives", str(tiny_dataset)])
    assert res.exit_code == 0, res.output
    text = out.read_text()
    assert "box-derived" in text and "hand recall" in text and "localised" in text
    assert out.with_suffix(".json").is_file() and out.with_suffix(".png").is_file()
