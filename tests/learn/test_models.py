"""The shared model tester: every registered network, channel/class variants, odd sizes, overfit."""

from __future__ import annotations

from inspect import signature

import numpy as np
import pytest
import torch
from torch import nn

from learn.classical.vgg_svm import VggSvmClassifier, extract_features
from learn.config import FINETUNE_TEST_C, VggSvmConfig
from learn.models import MODELS, count_parameters, create_model, prepare_for_inference
from learn.models.blocks import VGG16_STAGES, scaled
from learn.models.fcn import FCN16s
from learn.models.handsnet import HandsNet
from learn.models.vgg import VGGEncoder, load_vgg_weights
from learn.train.optim import (
    load_weights,
    lr_factors_by_parameter,
    make_optimizer,
    make_scheduler,
    param_groups,
)
from tactile.errors import ConfigError, DataError

ARCHS = sorted(a for a, m in MODELS.items() if m.task != "sequence")  # test_action_models: those
TINY_WIDTH = 0.125
COMPACT = ("compactseg", "handparts")
SIZES = [(37, 53), (68, 100)]


def make(arch: str, num_classes: int, in_channels: int = 1, size=(37, 53), **kw) -> nn.Module:
    """A small instance of ``arch`` (tiny width; HandsNet is fixed by the paper)."""
    kw.update({"num_classes": num_classes, "in_channels": in_channels})
    if arch == "handsnet":
        kw["input_size"] = size
    elif arch not in COMPACT:  # the compact networks are small at their own width 1
        kw["width"] = TINY_WIDTH
    return create_model(arch, **kw)


def expected_shape(model: nn.Module, batch: int, size: tuple[int, int]) -> tuple:
    if model.task == "classification":
        return (batch, model.num_classes)
    if model.task == "both":  # hand / non-hand, then the parts
        return ((batch, 2), (batch, model.num_classes, *size))
    return (batch, model.num_classes, *size)


def outputs(y) -> tuple[torch.Tensor, ...]:
    return y if isinstance(y, tuple) else (y,)


def shape_of(y) -> tuple:
    return tuple(tuple(o.shape) for o in y) if isinstance(y, tuple) else tuple(y.shape)


@pytest.mark.parametrize("size", SIZES)
@pytest.mark.parametrize("num_classes", [2, 7])
@pytest.mark.parametrize("in_channels", [1, 3])
@pytest.mark.parametrize("arch", ARCHS)
def test_forward_backward(arch, in_channels, num_classes, size):
    torch.manual_seed(0)
    model = make(arch, num_classes, in_channels, size)
    x = torch.rand(2, in_channels, *size)
    y = model(x)
    assert shape_of(y) == expected_shape(model, 2, size)
    assert all(torch.isfinite(o).all() for o in outputs(y))
    sum(o.square().mean() for o in outputs(y)).backward()
    for name, p in model.named_parameters():
        if p.requires_grad:
            assert p.grad is not None and torch.isfinite(p.grad).all(), name
    model.eval()
    with torch.no_grad():
        assert shape_of(model(x)) == shape_of(y)


@pytest.mark.parametrize("arch", ARCHS)
def test_prepare_for_inference_keeps_outputs(arch):
    torch.manual_seed(0)
    model = make(arch, num_classes=3)
    model.train()(torch.rand(4, 1, 37, 53))  # move the BN running statistics off their init
    fast = prepare_for_inference(model)
    assert not any(isinstance(m, nn.BatchNorm2d) for m in fast.modules())
    x = torch.rand(2, 1, 37, 53)
    with torch.no_grad():
        torch.testing.assert_close(fast(x), model.eval()(x), rtol=1e-4, atol=1e-5)


def test_unknown_arch_lists_choices():
    with pytest.raises(KeyError, match=r"handsnet.*segnet"):
        create_model("segnett")


def test_handsnet_is_table_1():
    model = HandsNet()
    assert count_parameters(model) == 670_338  # pinned: Table 1 at 68 × 100, padding 1
    convs = [m for m in model.modules() if isinstance(m, nn.Conv2d)]
    assert [(c.out_channels, c.kernel_size[0]) for c in convs] == [
        (32, 7),
        (64, 5),
        (128, 3),
        (256, 3),
    ]
    drops = [m.p for m in model.modules() if isinstance(m, nn.Dropout)]
    assert drops == [0.1, 0.2, 0.6, 0.5]
    assert model.eval()(torch.rand(3, 1, 68, 100)).shape == (3, 2)
    with pytest.raises(ConfigError, match="input_size"):
        model(torch.rand(1, 1, 60, 100))
    with pytest.raises(ConfigError, match="too small"):
        HandsNet(input_size=(20, 100))


def test_handsnet_zero_init_output_starts_every_image_at_even_odds():
    from learn.config import HANDSNET, HANDSNET_PAPER

    assert HANDSNET.model.zero_init_output and not HANDSNET_PAPER.model.zero_init_output
    torch.manual_seed(0)
    model = create_model("handsnet", **HANDSNET.model.kwargs()).eval()
    last = model.classifier[-1]
    assert torch.count_nonzero(last.weight) == 0 and torch.count_nonzero(last.bias) == 0
    probs = model(torch.rand(4, 1, 68, 100)).softmax(1)
    torch.testing.assert_close(probs, torch.full((4, 2), 0.5))
    # the same layer is Glorot-random otherwise, and only the last layer is touched
    other = create_model("handsnet", **HANDSNET_PAPER.model.kwargs())
    assert torch.count_nonzero(other.classifier[-1].weight) == other.classifier[-1].weight.numel()
    assert all(
        torch.count_nonzero(p) > 0
        for n, p in model.named_parameters()
        if n.endswith("weight") and not n.startswith("classifier.7")
    )


def test_vgg16_layout_at_full_width():
    encoder = VGGEncoder(width=1.0)
    convs = [m for m in encoder.modules() if isinstance(m, nn.Conv2d)]
    assert [c.out_channels for c in convs] == [c for stage in VGG16_STAGES for c in stage]
    assert encoder.out_channels == [64, 128, 256, 512, 512]


def test_segnet_decoder_mirrors_encoder():
    model = create_model("segnet", num_classes=7, width=1.0)
    convs = [m for m in model.decoder.modules() if isinstance(m, nn.Conv2d)] + [model.classifier]
    assert [c.out_channels for c in convs] == [512] * 3 + [512, 512, 256] + [256, 256, 128] + [
        128,
        64,
    ] + [64, 7]
    assert isinstance(model.unpool, nn.MaxUnpool2d)


def test_fcn_upsamplers_start_bilinear():
    model = FCN16s(num_classes=3, width=TINY_WIDTH)
    const = torch.ones(1, 3, 4, 5)
    up2 = model.upscore2(const)
    assert up2.shape == (1, 3, 8, 10)
    assert torch.allclose(up2[..., 1:-1, 1:-1], torch.ones(()))
    assert model.upscore16(const).shape == (1, 3, 64, 80)
    assert not model.upscore16.weight.requires_grad


# ---- loading torchvision-format VGG16 weights -------------------------------------------------


def torchvision_vgg16_state(batch_norm: bool, width: float = 1.0) -> dict[str, torch.Tensor]:
    """A random float64 state dict with torchvision's ``vgg16`` / ``vgg16_bn`` key layout.

    ``width`` < 1 shrinks the channels (same keys) to keep the tests fast.
    """
    torch.manual_seed(0)
    g = torch.Generator().manual_seed(0)
    state, index, c_in = {}, 0, 3
    for stage in VGG16_STAGES:
        for c_out in (scaled(c, width) for c in stage):
            state[f"features.{index}.weight"] = torch.randn(c_out, c_in, 3, 3, generator=g) * 0.05
            state[f"features.{index}.bias"] = torch.randn(c_out, generator=g) * 0.1
            if batch_norm:
                bn = f"features.{index + 1}."
                state[bn + "weight"] = 1 + 0.1 * torch.randn(c_out, generator=g)
                state[bn + "bias"] = 0.1 * torch.randn(c_out, generator=g)
                state[bn + "running_mean"] = 0.1 * torch.randn(c_out, generator=g)
                state[bn + "running_var"] = 1 + torch.rand(c_out, generator=g)
                state[bn + "num_batches_tracked"] = torch.tensor(10)
            index, c_in = index + (3 if batch_norm else 2), c_out
        index += 1  # max pooling
    state["classifier.0.weight"] = torch.zeros(10, 20)
    return {k: v.double() if v.is_floating_point() else v for k, v in state.items()}


def reference_vgg(state: dict[str, torch.Tensor], x: torch.Tensor) -> torch.Tensor:
    """pool5 of the file's network, computed directly from its tensors (torchvision order)."""
    index = 0
    for stage in VGG16_STAGES:
        for _ in stage:
            key = f"features.{index}."
            x = nn.functional.conv2d(x, state[key + "weight"], state[key + "bias"], padding=1)
            bn = f"features.{index + 1}."
            if bn + "running_mean" in state:
                x = nn.functional.batch_norm(
                    x,
                    state[bn + "running_mean"],
                    state[bn + "running_var"],
                    state[bn + "weight"],
                    state[bn + "bias"],
                    eps=1e-5,
                )
                index += 1
            x, index = torch.relu(x), index + 2
        x, index = nn.functional.max_pool2d(x, 2, 2, ceil_mode=True), index + 1
    return x


@pytest.mark.parametrize(
    ("file_bn", "model_bn", "width"),
    [
        (False, False, 0.125),
        (False, True, 0.125),
        (True, False, 0.125),
        (True, True, 0.125),
        (True, True, 1.0),
    ],
)
def test_load_vgg_weights_from_file(tmp_path, file_bn, model_bn, width):
    state = torchvision_vgg16_state(file_bn, width)
    path = tmp_path / "vgg16.pth"
    torch.save(state, path)
    encoder = VGGEncoder(in_channels=1, width=width, batch_norm=model_bn).double()
    assert load_vgg_weights(encoder, path) == 13
    x = torch.rand(2, 1, 37, 45, dtype=torch.float64)
    with torch.no_grad():
        expected = reference_vgg(state, x.repeat(1, 3, 1, 1) / 3)  # RGB filters averaged
        got = encoder.eval()(x)[-1]
    torch.testing.assert_close(got, expected, rtol=1e-9, atol=1e-9)


def test_load_vgg_weights_rejects_other_widths():
    with pytest.raises(ConfigError, match=r"width=1\.0"):
        load_vgg_weights(VGGEncoder(width=0.5), torchvision_vgg16_state(False))
    with pytest.raises(ConfigError, match="13"):
        load_vgg_weights(VGGEncoder(width=1.0), {"features.0.weight": torch.zeros(64, 3, 3, 3)})


# ---- overfit one batch --------------------------------------------------------------------------


def one_batch(task: str, num_classes: int, size=(37, 53)) -> tuple[torch.Tensor, torch.Tensor]:
    """A fixed batch: random images with random labels, or blocky images whose blocks are labels."""
    g = torch.Generator().manual_seed(0)
    if task == "classification":
        x = torch.rand(8, 1, *size, generator=g)
        return x, torch.arange(8) % num_classes
    block = 16  # FCN-16s resolves 16-px cells (aligned at the top left, where it does not pad)
    coarse = torch.randint(0, num_classes, (2, 1, *(s // block + 1 for s in size)), generator=g)
    labels = coarse.repeat_interleave(block, -2).repeat_interleave(block, -1)
    labels = labels[..., : size[0], : size[1]]
    x = labels.float() / num_classes + 0.05 * torch.rand(labels.shape, generator=g)
    return x, labels[:, 0]


def score(model: nn.Module, x: torch.Tensor, y: torch.Tensor) -> float:
    """Accuracy of what the optimiser fitted: batch-norm on batch statistics, dropout off.

    (Eval-mode running statistics lag on a 2-image batch whose deepest maps are 2 × 2 px; they
    are an inference calibration matter, not what "overfits one batch" checks.)
    """
    dropouts = [m for m in model.modules() if isinstance(m, nn.Dropout | nn.Dropout2d)]
    for m in dropouts:
        m.eval()
    with torch.no_grad():
        out = model(x)
        acc = ((out[1] if isinstance(out, tuple) else out).argmax(1) == y).float().mean().item()
    for m in dropouts:
        m.train()
    return acc


@pytest.mark.parametrize("arch", ARCHS)
def test_overfits_one_batch(arch):
    torch.manual_seed(0)
    no_dropout = {"dropout": 0.0} if "dropout" in signature(MODELS[arch]).parameters else {}
    size = (37, 53)  # odd sizes; deepest maps 2 × 2 keep batch-norm statistics usable
    model = make(arch, 2 if arch in ("handsnet", "vgg16") else 7, size=size, **no_dropout)
    x, y = one_batch(model.task, model.num_classes, size)
    opt = torch.optim.Adam([p for p in model.parameters() if p.requires_grad], lr=3e-3)
    target = 1.0 if model.task == "classification" else 0.95
    parts = (lambda x: model(x)[1]) if model.task == "both" else model
    for step in range(150):
        loss = nn.functional.cross_entropy(parts(x), y)
        opt.zero_grad()
        loss.backward()
        opt.step()
        if step % 10 == 9 and score(model, x, y) >= target:
            break
    assert score(model, x, y) >= target, f"{arch}: {score(model, x, y):.3f} after {step + 1}"


# ---- fine-tuning and VGG features + SVM ----------------------------------------------------------


def test_load_weights_across_architectures_and_class_counts(tmp_path):
    source = make("vgg16", num_classes=2)
    torch.save({"model": source.state_dict(), "epoch": 3}, tmp_path / "ckpt.pt")
    target = make("segnet", num_classes=7)
    report = load_weights(target, tmp_path / "ckpt.pt")
    assert report.loaded and all(k.startswith("encoder.") for k in report.loaded)
    assert not [k for k in target.state_dict() if k.startswith("encoder.") and k in report.missing]
    torch.testing.assert_close(
        target.encoder.stages[0][0][0].weight, source.encoder.stages[0][0][0].weight
    )
    other = make("vgg16", num_classes=7)
    assert load_weights(other, source.state_dict()).shape_mismatch == ("fc8.weight", "fc8.bias")
    with pytest.raises(DataError, match="checkpoint"):
        load_weights(other, {"model": {"a": 1}})


def lr_at_epoch(epoch: int, lr_factor: float = 1.0, cfg=FINETUNE_TEST_C) -> float:
    """The step schedule in closed form: lr x factor x drop ** (epoch // period)."""
    return cfg.lr * lr_factor * cfg.lr_drop_factor ** (epoch // cfg.lr_drop_period_epochs)


def test_test_c_param_groups_and_schedule():
    model = HandsNet()
    optimizer = make_optimizer(model, FINETUNE_TEST_C)
    scheduler = make_scheduler(optimizer, FINETUNE_TEST_C)
    by_factor = {g["lr_factor"]: g for g in optimizer.param_groups}
    assert by_factor[0.1]["lr"] == pytest.approx(0.001) and by_factor[1.0]["lr"] == 0.01
    convs = [m for m in model.modules() if isinstance(m, nn.Conv2d)]
    first_two = {id(p) for c in convs[:2] for p in c.parameters()}
    assert {id(p) for p in by_factor[0.1]["params"]} == first_two
    assert sum(len(g["params"]) for g in optimizer.param_groups) == len(list(model.parameters()))
    for epoch in range(FINETUNE_TEST_C.epochs):
        for group in optimizer.param_groups:
            expected = lr_at_epoch(epoch, group["lr_factor"])
            assert group["lr"] == pytest.approx(expected)
        optimizer.step()
        scheduler.step()
    assert lr_at_epoch(60) == pytest.approx(0.005)


def test_lr_factor_selectors():
    model = make("fcn16s", num_classes=3)
    factors = lr_factors_by_parameter(model, {"last_layer": 0.0, "encoder.stages.0.*": 0.5})
    assert factors["score_pool4.weight"] == 0.0 and factors["encoder.stages.0.1.0.weight"] == 0.5
    groups = param_groups(model, 0.01, {"last_layer": 0.0})
    assert not model.score_pool4.weight.requires_grad
    assert all(p is not model.upscore16.weight for g in groups for p in g["params"])
    with pytest.raises(ConfigError, match="first_two_convs"):
        param_groups(model, 0.01, {"decoderr.*": 0.1})


def test_vgg_svm_separates_dark_from_bright():
    rng = np.random.default_rng(0)
    levels = np.repeat([0.2, 0.7], 20)
    images = 255 * np.clip(levels[:, None, None] + 0.1 * rng.random((40, 20, 30)), 0, 1)
    labels = np.repeat([0, 1], 20)
    torch.manual_seed(0)
    clf = VggSvmClassifier(make("vgg16", num_classes=2), VggSvmConfig(batch_size=16))
    assert clf.features(images.astype(np.uint8)).shape == (40, scaled(4096, TINY_WIDTH))
    clf.fit(images.astype(np.uint8), labels)
    assert (clf.predict(images.astype(np.uint8)) == labels).mean() == 1.0
    assert extract_features(clf.model, torch.rand(3, 1, 20, 30), "pool5").shape == (3, 64)
