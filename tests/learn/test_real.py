"""Scores on real box-labelled prints (`learn.evaluate.real`), the box folder as training data
(`learn.data.boxes`) and the fine-tuning experiment (`experiments.real_finetune`), on box
folders written here: the tiny set's hand prints, each part boxed around its pixels, and prints
drawn with known boxes; expected scores counted by hand or by a slow per-pixel loop."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image
from typer.testing import CliRunner

from experiments.real_finetune import FinetunePlan, run_finetune, subset
from handskin.cli import app
from learn.data.boxes import BoxFolderDataset
from learn.evaluate.real import evaluate_real, localise
from learn.infer.predict import load_predictor, predict_image
from learn.train.finetune import copies_of, shift_px, training_set
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


def _moved_by(a: np.ndarray, dy: int, dx: int) -> np.ndarray:
    """Slow reference: ``a`` (..., H, W) moved by whole pixels, zeros coming in."""
    out = np.zeros_like(a)
    h, w = a.shape[-2:]
    out[..., max(dy, 0) : h + min(dy, 0), max(dx, 0) : w + min(dx, 0)] = a[
        ..., max(-dy, 0) : h - max(dy, 0), max(-dx, 0) : w - max(dx, 0)
    ]
    return out


def test_moved_copies_are_the_prints_moved_by_whole_pixels():
    from learn.data.augment import moved_copies

    rng = np.random.default_rng(3)
    x = torch.from_numpy(rng.random((2, 1, 20, 31), dtype=np.float32))
    y = torch.from_numpy(rng.choice([0, 2, 4, IGNORE], (2, 20, 31)).astype(np.int64))
    xs, ys = moved_copies(x, y, 6, 3, 0.0, np.random.default_rng(0))
    assert xs.shape == (12, 1, 20, 31) and ys.shape == (12, 20, 31)
    assert torch.equal(xs[:2], x) and torch.equal(ys[:2], y)
    seen = set()
    for j in range(2, 12):
        src_x, src_y = x[j % 2].numpy(), y[j % 2].numpy()
        fits = [
            (dy, dx)
            for dy in range(-3, 4)
            for dx in range(-3, 4)
            if np.allclose(xs[j].numpy(), _moved_by(src_x, dy, dx), atol=1e-5)
            and np.array_equal(ys[j].numpy(), _moved_by(src_y, dy, dx))
        ]
        assert len(fits) == 1, f"copy {j} is no whole-pixel move of its print"
        seen.add(fits[0])
    assert len(seen) > 3  # the moves differ


def test_turned_copies_are_rigid_and_keep_their_labels():
    """Two labelled marks on a non-square image: every turned copy keeps the marks' distance
    (pixels square) and turns the line between them by no more than ``turn_deg``."""
    from learn.data.augment import moved_copies

    x = torch.zeros(1, 1, 31, 61)
    y = torch.zeros(1, 31, 61, dtype=torch.int64)
    for (r, c), part in (((10, 15), 3), ((20, 45), 5)):
        x[0, 0, r - 2 : r + 3, c - 2 : c + 3] = 1.0
        y[0, r - 2 : r + 3, c - 2 : c + 3] = part
    y[0, 0, 0] = IGNORE  # an unlabelled pixel moves like any other, or leaves the image
    xs, ys = moved_copies(x, y, 40, 2, 20.0, np.random.default_rng(1))
    assert set(torch.unique(ys).tolist()) <= {0, 3, 5, IGNORE}
    distance, angle = np.hypot(10, 30), np.arctan2(10, 30)
    turns = []
    for j in range(1, 40):
        centres = [np.argwhere(ys[j].numpy() == part).mean(0) for part in (3, 5)]
        d = centres[1] - centres[0]
        assert abs(np.hypot(*d) - distance) < 1.0
        turns.append(np.rad2deg(np.arctan2(d[0], d[1]) - angle))
        assert abs(float(xs[j].sum()) - 50.0) < 5.0  # the marks' ink, resampled
    assert max(np.abs(turns)) < 20.0 + 2.0 and max(np.abs(turns)) > 10.0


def test_both_starts_train_on_the_same_real_copies():
    from learn.data.load import TensorData

    plan, plain = FinetunePlan(), FinetunePlan(shift_mm=0.0, turn_deg=0.0)
    assert copies_of(10, plan, "simulation") == copies_of(10, plan, "random") == 30
    assert copies_of(342, plan, "random") == 2  # moved copies at every k
    assert (copies_of(10, plain, "simulation"), copies_of(10, plain, "random")) == (30, 1)
    assert shift_px(plan, (247, 362), (68, 100)) == 5  # 18 mm on a 3.6 mm input pixel
    real = TensorData(torch.rand(3, 1, 8, 9), torch.ones(3, 8, 9, dtype=torch.int64))
    sim = TensorData(torch.ones(10, 1, 8, 9), torch.zeros(10, 8, 9, dtype=torch.int64))
    x, y = training_set(real, sim, 3, 1, plan, 0)
    assert x.shape == (10 + 9, 1, 8, 9) and torch.equal(x[:10], sim.x)
    assert torch.equal(x[10:13], real.x) and torch.equal(y[10:13], real.y)
    assert set(y[13:].unique().tolist()) <= {0, 1}  # moved: empty skin comes in
    alone = training_set(real, None, 3, 1, plan, 0)
    assert torch.equal(alone[0], x[10:]) and torch.equal(alone[1], y[10:])
    assert not torch.equal(training_set(real, None, 3, 1, plan, 1)[0], alone[0])  # per draw
    with pytest.raises(ConfigError, match=r"--turn-deg -1\.0"):
        FinetunePlan(turn_deg=-1.0)
    with pytest.raises(ConfigError, match="--shift-mm nan"):
        FinetunePlan(shift_mm=float("nan"))


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
    results written before replay and moved copies existed resume as runs without them."""
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
    plan = FinetunePlan(ks=(2,), draws=(1,), steps=3, threads=1, replay=0, shift_mm=0, turn_deg=0)
    run_finetune(checkpoints["segnet"], train_path, test_path, tmp_path / "old", plan, False)
    results = tmp_path / "old" / "results.json"
    old = json.loads(results.read_text())
    for field in ("replay_from", "replay_fingerprint"):
        del old["key"][field]
    for field in ("replay", "shift_mm", "turn_deg"):
        del old["key"]["plan"][field]
    results.write_text(json.dumps(old))
    again = run_finetune(
        checkpoints["segnet"], train_path, test_path, tmp_path / "old", plan, False
    )
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


def test_finetune_command_is_the_experiments_run_on_all_prints(
    real_like, checkpoints, tiny_dataset, tmp_path
):
    """`handskin finetune` on a box folder trains what the experiment's pretrained run on all
    of that folder's prints trains: the same replay, copies and steps, so the same scores."""
    from experiments.real_finetune import localisation
    from learn.train.checkpoint import load_checkpoint, model_from_checkpoint, run_of

    train_path, test_path, train, test = real_like
    out = tmp_path / "mine"
    args = ["finetune", str(train_path), "--init", str(checkpoints["segnet"]), "--out", str(out)]
    flags = ["--steps", "3", "--replay", "3", "--threads", "1", "--no-progress"]
    res = CliRunner().invoke(app, [*args, *flags])
    assert res.exit_code == 0, res.output
    told = json.loads((out / "finetune.json").read_text())
    assert (told["real_prints"], told["copies"]) == (len(train), 2)
    assert Path(told["replay_from"]).resolve() == Path(tiny_dataset).resolve()
    ckpt = load_checkpoint(out / "best.pt")
    mine = localisation(model_from_checkpoint(ckpt)[0], run_of(ckpt, out), test)
    plan = FinetunePlan(ks=(len(train),), draws=(1,), steps=3, threads=1, replay=3)
    done = run_finetune(checkpoints["segnet"], train_path, test_path, tmp_path / "x", plan, False)
    theirs = next(r for r in done["runs"] if r["start"] == "simulation")
    assert {k: theirs[k] for k in mine} == mine
    start = load_checkpoint(checkpoints["segnet"])["model"]
    assert any(not torch.equal(start[n], w) for n, w in ckpt["model"].items())


@pytest.mark.parametrize(
    ("what", "expected"),
    [
        ("dataset", "REAL .*: not a box folder"),
        ("classifier", "--init .*: a 'classify' network"),
        ("turn", r"--turn-deg 200\.0"),
        ("replay", "--replay 100000"),
        ("run", "already holds a run"),
    ],
)
def test_finetune_command_refuses_bad_input_before_any_work(
    real_like, checkpoints, tiny_dataset, tmp_path, what, expected
):
    train_path = real_like[0]
    real, init = str(train_path), str(checkpoints["segnet"])
    out, extra = tmp_path / "mine", []
    if what == "dataset":
        real = str(tiny_dataset)
    elif what == "classifier":
        init = str(checkpoints["handsnet"])
    elif what == "turn":
        extra = ["--turn-deg", "200"]
    elif what == "replay":
        extra = ["--replay", "100000"]
    else:
        out.mkdir()
        (out / "best.pt").write_bytes(b"weights")
    args = ["finetune", real, "--init", init, "--out", str(out), "--no-progress", *extra]
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 2
    assert re.search(expected, res.output), res.output
    if what == "run":
        assert sorted(p.name for p in out.iterdir()) == ["best.pt"]
        assert (out / "best.pt").read_bytes() == b"weights"
    else:
        assert not out.exists()


def test_train_init_on_a_box_folder_points_to_finetune(real_like, checkpoints, tmp_path):
    train_path = real_like[0]
    args = ["train", str(train_path), "--arch", "segnet", "--init", str(checkpoints["segnet"])]
    flags = ["--epochs", "1", "--out", str(tmp_path / "run"), "--no-progress"]
    res = CliRunner().invoke(app, [*args, *flags])
    assert res.exit_code == 0, res.output
    assert "handskin finetune" in res.output
