"""The contactor-type head (`learn.aux_types`, ``RunConfig.aux_types_weight``): its targets
against the dataset's own JSON, its loss against a numpy computation, checkpoints that hold the
plain network, exact resumption, and the configurations it refuses."""

from __future__ import annotations

import dataclasses
import json

import h5py
import numpy as np
import pytest
import torch

from learn.aux_types import HAND_TYPE, TypeHead, type_targets
from learn.checkpoint import load_checkpoint
from learn.models import create_model
from learn.train import RunConfig, fit, load_data, train_step
from tactile.errors import ConfigError

from .conftest import N_HAND, N_OTHER, SIZE


@pytest.fixture(autouse=True)
def _one_thread():
    torch.set_num_threads(1)


@pytest.fixture(scope="module")
def typed_dataset(tiny_writer, tmp_path_factory):
    """The tiny set with a contactor JSON per sample (hands right or left, balls and discs)."""
    folder = tmp_path_factory.mktemp("typed") / "tiny"
    return tiny_writer(folder, list(range(N_HAND + N_OTHER)), contactors=True)


def aux_run(tiny_run, weight: float = 1.0, **train) -> RunConfig:
    return dataclasses.replace(tiny_run("handsnet", **train), aux_types_weight=weight)


def _log_softmax(z: np.ndarray) -> np.ndarray:
    z = z - z.max(axis=1, keepdims=True)
    return z - np.log(np.exp(z).sum(axis=1, keepdims=True))


def test_type_targets_follow_the_datasets_contactor_json(typed_dataset):
    with h5py.File(typed_dataset / "dataset.h5") as f:
        raw = f["samples/contactor"][()]
        is_hand = f["samples/is_hand"][()].astype(bool)
    indices = np.array([40, 3, 27, 11, 30])  # any order
    ids, names = type_targets(typed_dataset, indices, is_hand[indices])
    expected = []
    for i in indices:
        c = json.loads(raw[i])
        expected.append(HAND_TYPE if is_hand[i] else f"{c['kind']}: {c['type']}")
    assert [names[k] for k in ids] == expected
    assert names == (HAND_TYPE, "object: ball", "object: disc")  # left and right hands are one


def test_loss_is_the_class_ce_plus_the_weighted_type_ce_of_the_output_layers_input(tiny_run):
    """One step's loss against numpy: CE of the class logits plus weight × CE of the head's
    logits, the head reading the input of the network's output layer (taken here by a hook of
    the test's own)."""
    run = aux_run(tiny_run, weight=0.7)
    torch.manual_seed(0)
    model = create_model("handsnet", **run.model.kwargs()).eval()  # eval: no dropout draws
    head = TypeHead(model, 3, run.aux_types_weight)
    x = torch.rand(6, 1, *SIZE)
    y, types = torch.tensor([0, 1, 1, 0, 1, 0]), torch.tensor([1, 0, 0, 2, 0, 1])
    seen = {}
    model.classifier[-1].register_forward_hook(lambda m, i, o: seen.update(h=i[0], z=o))
    optimizer = torch.optim.SGD([*model.parameters(), *head.parameters()], lr=0.0)
    value = train_step(
        model, torch.nn.CrossEntropyLoss(), optimizer, x, y, "classify", aux=(head, types)
    )
    z = seen["z"].detach().numpy().astype(np.float64)
    w, b = (p.detach().numpy().astype(np.float64) for p in (head.linear.weight, head.linear.bias))
    t = seen["h"].detach().numpy().astype(np.float64) @ w.T + b
    expected = (
        -_log_softmax(z)[np.arange(6), y.numpy()].mean()
        - 0.7 * _log_softmax(t)[np.arange(6), types.numpy()].mean()
    )
    assert value == pytest.approx(expected, rel=1e-5)


def test_checkpoints_hold_the_plain_network_and_a_cut_run_resumes_exactly(
    typed_dataset, tiny_run, tmp_path
):
    run = aux_run(tiny_run, epochs=2)
    data = load_data(typed_dataset, run)
    assert data.type_names == (HAND_TYPE, "object: ball", "object: disc")
    full = fit(run, data, tmp_path / "full", progress=False)
    fit(run, data, tmp_path / "cut", progress=False, stop_after_epoch=1)
    resumed = fit(run, data, tmp_path / "cut", resume=True, progress=False)
    assert [h["train_loss"] for h in resumed.history] == [h["train_loss"] for h in full.history]
    best, last = (load_checkpoint(tmp_path / "full" / n) for n in ("best.pt", "last.pt"))
    plain = create_model("handsnet", **run.model.kwargs())
    plain.load_state_dict(best["model"])  # strict: exactly the classifier's weights
    assert "type_head" in last and "type_head" not in best
    assert last["type_head"]["linear.weight"].shape == (3, 32)  # HandsNet's 32 hidden units
    without = fit(tiny_run("handsnet", epochs=2), data, None, progress=False)
    assert without.history[0]["train_loss"] != full.history[0]["train_loss"]


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"aux_types_weight": -1.0}, "weight >= 0"),
        ({"aux_types_weight": 1.0, "mixup_alpha": 0.2}, "set one of them to 0"),
    ],
)
def test_bad_type_head_settings_are_refused(tiny_run, change, match):
    with pytest.raises(ConfigError, match=match):
        dataclasses.replace(tiny_run("handsnet"), **change)


def test_a_segmenter_cannot_take_a_type_head(tiny_run):
    with pytest.raises(ConfigError, match="classifier"):
        dataclasses.replace(tiny_run("segnet"), aux_types_weight=1.0)


def test_data_without_contactor_types_are_refused_before_training(tiny_dataset, tiny_run, tmp_path):
    run = aux_run(tiny_run)
    with pytest.raises(ConfigError, match="record no contactor type"):
        load_data(tiny_dataset, run)  # this tiny set has no contactor field
    plain = load_data(tiny_dataset, tiny_run("handsnet"))
    with pytest.raises(ConfigError, match="carry no contactor types"):
        fit(run, plain, tmp_path / "run", progress=False)
    assert not (tmp_path / "run").exists()


def test_fault_aware_fine_tuning_takes_a_type_head_checkpoint(typed_dataset, tiny_run, tmp_path):
    """`handskin experiment fault-aware` retrains from a checkpoint's configuration; the faulty
    copies carry no contactor types, so the head (a training aid) is left out there."""
    from learn.experiments.fault_aware import FaultAwareScale, fault_aware_model
    from learn.experiments.robustness_setup import Scale

    run = aux_run(tiny_run, epochs=1)
    fit(run, load_data(typed_dataset, run), tmp_path / "aux", progress=False)
    scale = FaultAwareScale(
        Scale(1, None, 4, n_spots=(2,), radii_mm=(20.0,), fractions=(0.0, 0.6)),
        epochs=(1, 1),
        n_train=(8, 8),
        copies=1,
    )
    out = fault_aware_model(
        tmp_path / "aux" / "best.pt",
        typed_dataset,
        tmp_path / "fa",
        epochs=1,
        n_train=8,
        scale=scale,
        seed=0,
        progress=False,
    )
    tuned = load_checkpoint(out["checkpoint"])
    assert tuned["config"]["aux_types_weight"] == 0.0 and out["train_images"] == 16
    plain = create_model("handsnet", **run.model.kwargs())
    plain.load_state_dict(tuned["model"], strict=True)
