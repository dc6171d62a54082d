"""Knowledge distillation (`learn.distill`, ``RunConfig.distill_from``): the loss against numpy and
its closed-form gradient, the teacher's view-averaged targets against a hand computation, a
student that follows a constant teacher over its labels, exact resumption, and the teachers and
settings it refuses before any work."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch
from torch import nn

from learn.checkpoint import make_checkpoint, save_checkpoint
from learn.distill import Distiller, check_teacher, teacher_probs
from learn.models import create_model
from learn.train import fit, load_data
from tactile.config import to_dict
from tactile.errors import ConfigError, DataError

from .conftest import SIZE
from .test_leakage import resplit


@pytest.fixture(autouse=True)
def _one_thread():
    torch.set_num_threads(1)


def _softmax(z: np.ndarray) -> np.ndarray:
    e = np.exp(z - z.max(axis=1, keepdims=True))
    return e / e.sum(axis=1, keepdims=True)


def test_loss_is_the_weighted_mix_of_labels_and_tempered_kl():
    rng = np.random.default_rng(0)
    p = _softmax(rng.normal(size=(10, 3)))  # teacher targets of 10 samples
    z = rng.normal(size=(4, 3)) * 2  # student logits of a batch
    samples = np.array([7, 2, 2, 9])
    d = Distiller(torch.tensor(p, dtype=torch.float32), weight=0.3, temperature=3.0)
    got = d.loss(torch.tensor(0.7), torch.tensor(z, dtype=torch.float32), torch.tensor(samples))
    q = _softmax(z / 3.0)
    kl = (p[samples] * np.log(p[samples] / q)).sum(axis=1).mean()
    assert float(got) == pytest.approx(0.7 * 0.7 + 0.3 * 9.0 * kl, rel=1e-5)


def test_soft_term_gradient_is_t_times_student_minus_teacher():
    """d/dz of T^2 KL(p || softmax(z / T)), batch-averaged, is T (softmax(z / T) - p) / B."""
    rng = np.random.default_rng(1)
    p = _softmax(rng.normal(size=(5, 2)) * 3)
    z = torch.tensor(rng.normal(size=(5, 2)) * 4, dtype=torch.float64, requires_grad=True)
    d = Distiller(torch.tensor(p), weight=1.0, temperature=2.5)
    d.loss(torch.tensor(0.0, dtype=torch.float64), z, torch.arange(5)).backward()
    want = 2.5 * (_softmax(z.detach().numpy() / 2.5) - p) / 5
    np.testing.assert_allclose(z.grad.numpy(), want, rtol=1e-10, atol=1e-12)


class HalfSums(nn.Module):
    """Logits (sum of the left half's pixels, sum of the top half's pixels): reversing the
    columns changes the first, reversing the rows the second."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h, w = x.shape[-2:]
        return torch.stack([x[..., : w // 2].sum((1, 2, 3)), x[..., : h // 2, :].sum((1, 2, 3))], 1)


def test_teacher_targets_are_the_tempered_softmax_averaged_over_the_views():
    rng = np.random.default_rng(2)
    x = rng.uniform(size=(7, 1, 4, 6))
    got = teacher_probs(
        HalfSums(),
        torch.tensor(x, dtype=torch.float32),
        torch.tensor([0, 1, 2]),
        temperature=2.0,
        batch_size=3,
    )
    left, right = x[..., :3].sum((1, 2, 3)), x[..., 3:].sum((1, 2, 3))
    top, bottom = x[..., :2, :].sum((1, 2, 3)), x[..., 2:, :].sum((1, 2, 3))
    views = [np.stack(v, 1) for v in ((left, top), (right, top), (left, bottom))]
    want = np.mean([_softmax(v / 2.0) for v in views], axis=0)
    np.testing.assert_allclose(got.numpy(), want, rtol=1e-5)


def constant_teacher(run, data_path, folder, logits=(4.0, -4.0)):
    """A HandsNet checkpoint (of ``run``'s input) that says class 0 for every image: its output
    layer's weights zero, its biases ``logits``."""
    net = create_model("handsnet", **run.model.kwargs())
    with torch.no_grad():
        net.classifier[-1].weight.zero_()
        net.classifier[-1].bias.copy_(torch.tensor(logits))
    ckpt = make_checkpoint(
        net,
        to_dict(run),
        epoch=1,
        best_metric=float("nan"),
        task="classify",
        data={"path": str(data_path)},
    )
    return save_checkpoint(ckpt, folder / "teacher.pt")


def test_a_student_on_the_teacher_alone_follows_it_not_the_labels(tiny_dataset, tiny_run, tmp_path):
    run = tiny_run("handsnet", epochs=3)
    data = load_data(tiny_dataset, run)
    teacher = constant_teacher(run, tiny_dataset, tmp_path)
    student = dataclasses.replace(
        run, distill_from=str(teacher), distill_weight=1.0, distill_temperature=1.0
    )
    plain = fit(run, data, None, progress=False).model.eval()
    taught = fit(student, data, None, progress=False).model.eval()
    with torch.no_grad():
        assert plain(data.train.x).argmax(1).eq(1).any()  # labels alone: some hands found
        assert taught(data.train.x).argmax(1).eq(0).all()  # the teacher's class everywhere


def test_a_distilled_run_cut_and_resumed_equals_one_run(tiny_dataset, tiny_run, tmp_path):
    run = tiny_run("handsnet", epochs=2)
    data = load_data(tiny_dataset, run)
    student = dataclasses.replace(
        run, distill_from=str(constant_teacher(run, tiny_dataset, tmp_path))
    )
    full = fit(student, data, tmp_path / "full", progress=False)
    fit(student, data, tmp_path / "cut", progress=False, stop_after_epoch=1)
    resumed = fit(student, data, tmp_path / "cut", resume=True, progress=False)
    assert [h["train_loss"] for h in resumed.history] == [h["train_loss"] for h in full.history]
    assert (
        full.history[0]["train_loss"]
        != fit(run, data, None, progress=False).history[0]["train_loss"]
    )  # the teacher's term is in the loss


def test_teachers_that_do_not_fit_are_refused(tiny_dataset, tiny_run, checkpoints, tmp_path):
    run = tiny_run("handsnet")
    with pytest.raises(DataError, match="no teacher checkpoint"):
        check_teacher(
            dataclasses.replace(run, distill_from=str(tmp_path / "none.pt")), tiny_dataset
        )
    with pytest.raises(ConfigError, match="task segment"):
        check_teacher(
            dataclasses.replace(run, distill_from=str(checkpoints["segnet"])), tiny_dataset
        )
    model = dataclasses.replace(run.model, input_size=(36, 52))
    other_size = dataclasses.replace(run, model=model)
    with pytest.raises(ConfigError, match=r"input_size \(32, 48\) \(the student's: \(36, 52\)\)"):
        check_teacher(
            dataclasses.replace(other_size, distill_from=str(checkpoints["handsnet"])), tiny_dataset
        )
    assert SIZE == (32, 48)


def test_a_teacher_that_trained_on_the_test_people_is_refused(
    tiny_dataset, tiny_run, checkpoints, tmp_path
):
    from tactile.dataset.reader import DatasetReader

    with DatasetReader(tiny_dataset) as ds:
        train = ds.splits["train"]
    other = resplit(tiny_dataset, tmp_path / "other", train[::2])  # its test: teacher's train
    run = dataclasses.replace(tiny_run("handsnet"), distill_from=str(checkpoints["handsnet"]))
    with pytest.raises(ConfigError, match="the student would learn its test people"):
        check_teacher(run, other)
    assert check_teacher(run, tiny_dataset)["config"]  # its own dataset: accepted
    with pytest.warns(UserWarning, match="validation split"):
        check_teacher(
            dataclasses.replace(run, train=dataclasses.replace(run.train, seed=5)), tiny_dataset
        )


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"distill_weight": 0.0}, r"in \(0, 1\]"),
        ({"distill_weight": 1.5}, r"in \(0, 1\]"),
        ({"distill_temperature": 0.0}, "temperature be > 0"),
        ({"distill_from": "t.pt", "mixup_alpha": 0.2}, "unmixed images"),
    ],
)
def test_bad_distillation_settings_are_refused(tiny_run, change, match):
    with pytest.raises(ConfigError, match=match):
        dataclasses.replace(tiny_run("handsnet"), **change)


def test_the_train_command_distils_and_refuses_a_segmenter_before_work(
    tiny_dataset, checkpoints, tmp_path
):
    import typer
    from typer.testing import CliRunner

    from learn.checkpoint import load_checkpoint
    from learn.cli import register

    app = typer.Typer()
    register(app)
    config = tmp_path / "run.toml"
    config.write_text(
        "threads = 1\ndistill_weight = 0.25\n[model]\ninput_size = [32, 48]\n"
        "[train]\nepochs = 1\nbatch_size = 16\n"
    )
    base = ["train", str(tiny_dataset), "--config", str(config), "--no-progress"]
    res = CliRunner().invoke(
        app, [*base, "--out", str(tmp_path / "seg"), "--distill-from", str(checkpoints["segnet"])]
    )
    assert res.exit_code == 2 and "task segment" in res.output, res.output
    assert not (tmp_path / "seg").exists()
    res = CliRunner().invoke(
        app, [*base, "--out", str(tmp_path / "kd"), "--distill-from", str(checkpoints["handsnet"])]
    )
    assert res.exit_code == 0, res.output
    cfg = load_checkpoint(tmp_path / "kd" / "best.pt")["config"]
    assert (cfg["distill_from"], cfg["distill_weight"]) == (str(checkpoints["handsnet"]), 0.25)


def test_the_train_command_checks_the_teacher_once(tiny_dataset, checkpoints, tmp_path):
    """The teacher is checked before the data load and not again in fit: one split warning."""
    import warnings

    import typer
    from typer.testing import CliRunner

    from learn.cli import register

    app = typer.Typer()
    register(app)
    config = tmp_path / "run.toml"  # another seed: another validation split than the teacher's
    config.write_text(
        "threads = 1\n[model]\ninput_size = [32, 48]\n"
        "[train]\nepochs = 1\nbatch_size = 16\nseed = 5\n"
    )
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = CliRunner().invoke(
            app,
            [
                "train",
                str(tiny_dataset),
                "--config",
                str(config),
                "--no-progress",
                "--out",
                str(tmp_path / "kd"),
                "--distill-from",
                str(checkpoints["handsnet"]),
            ],
        )
    assert res.exit_code == 0, res.output
    split = [w for w in caught if "validation split" in str(w.message)]
    assert len(split) == 1, [str(w.message) for w in split]
