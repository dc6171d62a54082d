"""The training loop: learning, subject-disjoint validation, checkpoints, resumption, fine-tuning
lr factors, TOML run configs and cross-validation folds."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from learn.config import FINETUNE_TEST_C, RunConfig, load_run_config, replace_train, run_from_dict
from learn.data.dataset import TorchTactileDataset
from learn.data.load import TensorData, group_ids, load_data, validation_split
from learn.train.checkpoint import load_checkpoint, model_from_checkpoint
from learn.train.crossval import cross_validate, folds, parse_grid
from learn.train.loop import build, fit, get_batch, views_of
from learn.train.validation import evaluate_tensors
from tactile.config import to_dict
from tactile.dataset import open_dataset
from tactile.errors import ConfigError

from .conftest import N_HAND, N_OTHER, resume_after_edit


@pytest.fixture(autouse=True)
def _one_thread():
    torch.set_num_threads(1)


def test_handsnet_learns_above_chance(tiny_dataset, tiny_run):
    run = tiny_run("handsnet", epochs=6, batch_size=8)
    data = load_data(tiny_dataset, run)
    result = fit(run, data, None, progress=False)
    acc = evaluate_tensors(result.model, data.test, 2).metrics["accuracy"]
    assert acc > 0.6  # chance: 0.5 (8 hands, 8 non-hands in the test split)
    assert result.history[-1]["train_loss"] < result.history[0]["train_loss"]


def test_segnet_loss_decreases(tiny_dataset, tiny_run):
    run = tiny_run("segnet", epochs=3)
    result = fit(run, load_data(tiny_dataset, run), None, progress=False)
    losses = [h["train_loss"] for h in result.history]
    assert losses[-1] < losses[0] and 0.0 <= result.best_metric <= 1.0


def test_validation_is_subject_disjoint(tiny_dataset):
    ds = TorchTactileDataset(tiny_dataset, split="train", flips=False)
    train, val = validation_split(ds, 0.3, seed=0)
    (_, s_tr, i_tr), (c_va, s_va, i_va) = group_ids(train), group_ids(val)
    assert set(s_tr[s_tr >= 0]).isdisjoint(s_va[s_va >= 0])
    assert set(i_tr[i_tr >= 0]).isdisjoint(i_va[i_va >= 0])
    assert set(c_va) == {0, 1} and set(train.indices).isdisjoint(val.indices)
    assert set(np.r_[train.indices, val.indices]) == set(open_dataset(tiny_dataset).splits["train"])


def test_validation_inside_a_keyed_split_is_keyed(tiny_writer, keyed_reference, tmp_path):
    """A dataset split by key gets a keyed validation split: the train split's units drawn again
    with the training seed on stream 1 (independent of the test split's stream 0)."""
    reference, sides_of = keyed_reference
    folder = tiny_writer(tmp_path / "keyed", list(range(N_HAND + N_OTHER)), split="keyed")
    with open_dataset(folder) as ds:
        assert ds.attrs["split_method"] == "keyed"
        subject, instance = ds["subject_id"][()], ds["instance_id"][()]
        assert sides_of(subject, instance, ds.splits["train"]) == reference(
            set(sides_of(subject, instance, ds.splits["train"])), seed=3
        )
    ds = TorchTactileDataset(folder, split="train", flips=False)
    for seed in (0, 7):
        train, val = validation_split(ds, 0.3, seed=seed)
        keep = np.sort(ds.indices)
        sides = sides_of(
            subject[keep], instance[keep], np.flatnonzero(np.isin(keep, train.indices))
        )
        assert sides == reference(set(sides), seed, fraction=0.7, stream=1)
        assert set(np.r_[train.indices, val.indices]) == set(keep)


def test_checkpoint_round_trip_and_resume(tiny_dataset, tiny_run, tmp_path):
    run = tiny_run("handsnet", epochs=2)
    data = load_data(tiny_dataset, run)
    full = fit(run, data, tmp_path / "full", progress=False)
    fit(run, data, tmp_path / "cut", progress=False, stop_after_epoch=1)
    resumed = fit(run, data, tmp_path / "cut", resume=True, progress=False)
    for a, b in zip(full.history, resumed.history, strict=True):
        assert a["train_loss"] == b["train_loss"] and a["val_metric"] == b["val_metric"]
    last_full = load_checkpoint(tmp_path / "full" / "last.pt")
    last_cut = load_checkpoint(tmp_path / "cut" / "last.pt")
    for k, v in last_full["model"].items():
        assert torch.equal(v, last_cut["model"][k]), k
    ckpt = load_checkpoint(tmp_path / "full" / "best.pt")  # torch.load safe mode
    assert {"model", "optimizer", "config", "epoch", "best_metric", "versions", "seed"} <= set(ckpt)
    assert run_from_dict(ckpt["config"]) == run and ckpt["config"] == to_dict(run)
    model, _ = model_from_checkpoint(ckpt)
    for k, v in model.state_dict().items():  # best.pt holds the trained weights bit for bit
        assert torch.equal(v, full.model.state_dict()[k]), k
    x = data.test.x[:4]
    with torch.no_grad():
        # Equal weights may still run other float32 kernels: a size-1 dimension's stride differs
        # between the trained and the loaded tensor, and oneDNN picks its path by the strides on
        # some CPUs (7e-7 apart on an Intel Xeon); so the outputs agree to 1e-5, not bit for bit.
        assert torch.allclose(model(x), full.model.eval()(x), rtol=1e-4, atol=1e-5)
    assert (tmp_path / "full" / "curves.png").stat().st_size > 0
    assert ckpt["init"] == "random"


def test_resume_a_checkpoint_older_than_a_config_key(tiny_dataset, tiny_run, tmp_path):
    """A last.pt written without a key (here ``patience_epochs``) resumes with its default, and
    one holding a retired option at its off value (``rot180 = false``) as if it were not there.
    Any other difference is still refused."""
    run = tiny_run("handsnet", epochs=2)
    data = load_data(tiny_dataset, run)

    def edit(config):
        config.pop("patience_epochs")
        config["rot180"] = False

    full, resumed = resume_after_edit(run, data, tmp_path, edit)
    assert [h["train_loss"] for h in resumed.history] == [h["train_loss"] for h in full.history]
    with pytest.raises(ConfigError, match="another configuration"):
        fit(replace_train(run, lr=0.5), data, tmp_path / "cut", resume=True, progress=False)


def test_checkpoint_records_its_start_through_a_resume(
    tiny_dataset, tiny_run, checkpoints, tmp_path
):
    run = tiny_run("handsnet", epochs=2)
    data = load_data(tiny_dataset, run)
    start = checkpoints["handsnet"]
    fit(run, data, tmp_path / "ft", init=start, progress=False, stop_after_epoch=1)
    assert load_checkpoint(tmp_path / "ft" / "last.pt")["init"] == str(start)
    fit(run, data, tmp_path / "ft", resume=True, progress=False)  # no init given on resume
    for name in ("last.pt", "best.pt"):
        assert load_checkpoint(tmp_path / "ft" / name)["init"] == str(start), name


def test_finetuning_applies_lr_factors(tiny_run, checkpoints):
    """The loop's start for Test C: the checkpoint's weights, lr x 0.1 on the first two
    convolutions, both groups halved after epoch 60 of the step schedule."""
    run = replace_train(tiny_run("handsnet"), **{**vars(FINETUNE_TEST_C), "epochs": 61})
    ckpt = load_checkpoint(checkpoints["handsnet"])
    model, optimizer, scheduler = build(run, ckpt)
    conv0 = ckpt["model"]["features.0.0.weight"]
    assert torch.equal(model.state_dict()["features.0.0.weight"], conv0)
    want = {0: {0.1: 0.001, 1.0: 0.01}, 59: {0.1: 0.001, 1.0: 0.01}, 60: {0.1: 5e-4, 1.0: 5e-3}}
    for epoch in range(61):
        if epoch in want:
            got = {g["lr_factor"]: g["lr"] for g in optimizer.param_groups}
            assert got == {f: pytest.approx(lr) for f, lr in want[epoch].items()}
        optimizer.step()
        scheduler.step()


@pytest.mark.parametrize(("flips", "expected"), [(True, [0, 1, 2]), (False, [0])])
def test_training_views_against_numpy(flips, expected):
    """Item j of an epoch is sample j // V in view views[j % V]: as is, columns reversed or rows
    reversed, for images and label images."""
    rng = np.random.default_rng(0)
    x, y = rng.random((5, 1, 4, 6)), rng.integers(0, 7, (5, 4, 6))
    data = TensorData(torch.from_numpy(x), torch.from_numpy(y))
    run = RunConfig(flips=flips)
    views = views_of(run)
    assert views.tolist() == expected
    items = torch.arange(5 * len(views))
    xb, yb = get_batch(data, items, views)
    ref = {
        0: lambda a: a,
        1: lambda a: a[..., ::-1],
        2: lambda a: a[..., ::-1, :],
    }
    for j in range(len(items)):
        s, v = divmod(j, len(views))
        np.testing.assert_array_equal(xb[j].numpy(), ref[expected[v]](x[s]))
        np.testing.assert_array_equal(yb[j].numpy(), ref[expected[v]](y[s]))


def test_run_config_toml(tmp_path):
    path = tmp_path / "run.toml"
    path.write_text(
        'val_fraction = 0.2\n[model]\narch = "handsnet"\ninput_size = [32, 48]\n'
        "[train]\nlr = 0.05\nlr_factors = { first_two_convs = 0.1 }\n"
    )
    run = load_run_config(path)
    assert run.val_fraction == 0.2 and run.model.input_size == (32, 48)
    assert run.train.lr == 0.05 and dict(run.train.lr_factors) == {"first_two_convs": 0.1}
    path.write_text("rot180 = true\n")  # a retired option: refused, with where to read why
    with pytest.raises(ConfigError, match=r"rot180.*docs/findings.md"):
        load_run_config(path)
    path.write_text("[train]\nlearning_rate = 0.1\n")
    with pytest.raises(ConfigError, match="learning_rate"):
        load_run_config(path)
    with pytest.raises(ConfigError, match="unknown arch"):
        run_from_dict({"model": {"arch": "resnet"}})


def test_crossval_folds_are_group_disjoint(tiny_dataset, tiny_run):
    assert parse_grid("train.lr=0.01,0.001; threads=1") == {
        "train.lr": [0.01, 0.001],
        "threads": [1],
    }
    ds = TorchTactileDataset(tiny_dataset, split="train", flips=False)
    _, subject, instance = group_ids(ds)
    for train, val in folds(ds, 3, seed=0):
        for ids in (subject, instance):
            assert set(ids[train][ids[train] >= 0]).isdisjoint(ids[val][ids[val] >= 0])
    cv = cross_validate(tiny_run(epochs=1), tiny_dataset, {"train.lr": [0.01, 0.001]}, k=2)
    assert len(cv.rows) == 2 and len(cv.rows[0]["fold_metrics"]) == 2
    assert cv.best_run.train.lr == cv.best_changes["train.lr"]
    with pytest.raises(ConfigError, match="key=v1"):
        parse_grid("train.lr")


@pytest.mark.parametrize(
    ("optimizer", "expected"), [("adamw", 0.95), ("adam", 0.9), ("sgdm", 0.95)]
)
def test_weight_decay_alone_moves_a_weight_as_each_optimizer_defines(optimizer, expected):
    """With a zero loss gradient, one step from w = 1 (lr 0.1, weight_decay 0.5): AdamW decays
    by lr * wd (w = 0.95, Loshchilov & Hutter); Adam's L2 term is normalised by its own
    running scale, a step of ~lr (w ~ 0.9); SGD's first step is lr * wd * w (0.95)."""
    from learn.config import TrainConfig
    from learn.train.optim import make_optimizer

    model = torch.nn.Linear(1, 1, bias=False)
    torch.nn.init.ones_(model.weight)
    opt = make_optimizer(model, TrainConfig(optimizer=optimizer, lr=0.1, weight_decay=0.5))
    (model.weight * 0.0).sum().backward()
    opt.step()
    assert model.weight.item() == pytest.approx(expected, abs=1e-6)
    with pytest.raises(ConfigError, match="adamw"):
        TrainConfig(optimizer="rmsprop")
