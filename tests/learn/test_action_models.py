"""The model tester of the action network (sequences in): forward and backward on a tiny input,
channel and class variants, overfitting one batch; the training-time prefix cut against numpy."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from torch import nn

from learn.models import MODELS, create_model
from learn.models.action import RandomPrefix
from tactile.errors import ConfigError

ARCHS = sorted(a for a, m in MODELS.items() if m.task == "sequence")


def make(arch: str, num_classes: int, in_channels: int = 1, **kw) -> nn.Module:
    return create_model(arch, num_classes=num_classes, in_channels=in_channels, width=0.25, **kw)


def test_the_action_network_is_registered():
    assert ARCHS == ["action_3d"]


@pytest.mark.parametrize("shape", [(3, 24, 30), (7, 29, 37)])
@pytest.mark.parametrize("num_classes", [2, 8])
@pytest.mark.parametrize("in_channels", [1, 3])
@pytest.mark.parametrize("arch", ARCHS)
def test_forward_backward(arch, in_channels, num_classes, shape):
    torch.manual_seed(0)
    model = make(arch, num_classes, in_channels)
    t, h, w = shape
    x = torch.rand(2, t, in_channels, h, w)
    x[1, t - 2 :] = 0  # a shorter press
    y = model(x)
    assert y.shape == (2, num_classes) and torch.isfinite(y).all()
    y.square().mean().backward()
    for name, p in model.named_parameters():
        assert p.grad is not None and torch.isfinite(p.grad).all(), name
    model.eval()
    with torch.no_grad():
        assert model(x).shape == y.shape


@pytest.mark.parametrize("arch", ARCHS)
def test_eval_mode_answers_alone_as_in_a_batch(arch):
    torch.manual_seed(0)
    model = make(arch, 8)
    model.train()(torch.rand(4, 6, 1, 24, 30))  # move the batch-norm statistics off their init
    model.eval()
    x = torch.rand(3, 6, 1, 24, 30)
    x[0, 3:] = 0
    with torch.no_grad():
        torch.testing.assert_close(model(x[:1]), model(x)[:1], rtol=1e-4, atol=1e-5)


@pytest.mark.parametrize("arch", ARCHS)
def test_refuses_images_without_a_time_axis(arch):
    with pytest.raises(ConfigError, match=r"\(B, T, 1, h, w\)"):
        make(arch, 8)(torch.rand(2, 1, 32, 48))


@pytest.mark.parametrize("arch", ARCHS)
def test_overfits_one_batch(arch):
    """8 sequences of 4 random frames, one label each: memorised within 150 Adam steps."""
    torch.manual_seed(0)
    model = make(arch, 8, prefix_p=0.0, dropout=0.0)
    g = torch.Generator().manual_seed(0)
    x, y = torch.rand(8, 4, 1, 24, 24, generator=g), torch.arange(8)
    opt = torch.optim.Adam(model.parameters(), lr=1e-2)
    for step in range(150):
        loss = nn.functional.cross_entropy(model(x), y)
        opt.zero_grad()
        loss.backward()
        opt.step()
        if step % 10 == 9 and (model(x).argmax(1) == y).all():
            break
    assert (model(x).argmax(1) == y).all(), f"{arch}: not fitted after {step + 1} steps"


def test_random_prefix_keeps_a_prefix_of_each_press():
    torch.manual_seed(3)
    t = 8
    lengths = np.array([8, 5, 1, 3] * 64)
    x = torch.rand(len(lengths), t, 1, 4, 5) + 0.1
    for s, n in enumerate(lengths):
        x[s, n:] = 0
    cut = RandomPrefix(1.0).train()
    out = cut(x).numpy()
    kept = []
    for s, n in enumerate(lengths):  # numpy reference: the first k frames as they were, then 0
        k = int((np.abs(out[s]).reshape(t, -1).max(1) > 0).sum())
        assert 1 <= k <= n
        np.testing.assert_array_equal(out[s, :k], x[s, :k].numpy())
        assert (out[s, k:] == 0).all()
        kept.append(k)
    assert {k for k, n in zip(kept, lengths, strict=True) if n == 8} == set(range(1, 9))
    assert torch.equal(cut.eval()(x), x) and torch.equal(RandomPrefix(0.0).train()(x), x)
