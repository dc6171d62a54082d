"""Batch augmentations (`learn.augment`): random shifts (`RunConfig.shift_px`) and mixup
(`RunConfig.mixup_alpha`)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from learn.augment import mix_batch, mixup, random_shift
from learn.train import fit, load_data
from tactile.errors import ConfigError


def shifted_reference(a: np.ndarray, dy: int, dx: int) -> np.ndarray:
    """``a`` (..., H, W) moved by (dy, dx) pixels, zeros shifted in: a slow loop over pixels."""
    out = np.zeros_like(a)
    h, w = a.shape[-2:]
    for r in range(h):
        for c in range(w):
            if 0 <= r - dy < h and 0 <= c - dx < w:
                out[..., r, c] = a[..., r - dy, c - dx]
    return out


@pytest.mark.parametrize("channels", [1, 3])
def test_images_and_label_images_move_together_as_a_pixel_loop_moves_them(channels):
    rng = np.random.default_rng(0)
    x = rng.random((6, channels, 7, 9)).astype(np.float32)
    y = rng.integers(0, 7, (6, 7, 9))
    gen = torch.Generator().manual_seed(3)
    xs, ys = random_shift(torch.from_numpy(x), torch.from_numpy(y), 4, generator=gen)
    shifts = torch.randint(-4, 5, (6, 2), generator=torch.Generator().manual_seed(3)).numpy()
    assert np.abs(shifts).max() > 0
    for i, (dy, dx) in enumerate(shifts):
        np.testing.assert_array_equal(xs[i].numpy(), shifted_reference(x[i], dy, dx))
        np.testing.assert_array_equal(ys[i].numpy(), shifted_reference(y[i], dy, dx))


def test_class_targets_pass_through_and_zero_shift_is_the_identity():
    x, y = torch.rand(4, 1, 5, 5), torch.tensor([0, 1, 1, 0])
    xs, ys = random_shift(x, y, 2, generator=torch.Generator().manual_seed(0))
    assert torch.equal(ys, y) and xs.shape == x.shape
    assert random_shift(x, y, 0) == (x, y)
    with pytest.raises(ValueError, match="max_px"):
        random_shift(x, y, -1)


def test_every_shift_in_range_is_drawn_uniformly():
    x = torch.zeros(4000, 1, 11, 11)
    x[:, 0, 5, 5] = 1.0  # a dot in the middle: where it lands is the shift
    xs, _ = random_shift(x, torch.zeros(4000), 3, generator=torch.Generator().manual_seed(1))
    where = xs[:, 0].flatten(1).argmax(1)
    dy, dx = (where // 11 - 5).numpy(), (where % 11 - 5).numpy()
    for d in (dy, dx):
        counts = np.bincount(d + 3, minlength=7)
        assert len(counts) == 7  # -3 .. 3, nothing beyond
        # uniform: 4000 / 7 = 571 per value, binomial sd 22; allow 5 sd
        assert np.all(np.abs(counts - 4000 / 7) < 5 * 22)


def test_shift_is_range_checked_before_training():
    from learn.train import RunConfig

    with pytest.raises(ConfigError, match="shift_px"):
        RunConfig(shift_px=-1)
    with pytest.raises(ConfigError, match="shift_px"):
        RunConfig(shift_px=35)  # input 68 x 100: at most 34


def repeats_and_differs(dataset, run, **change) -> bool:
    """Whether one epoch of ``run`` with ``change`` gives the same training loss twice, and
    another one than ``run`` without it."""
    torch.set_num_threads(1)
    data = load_data(dataset, run)
    changed = dataclasses.replace(run, **change)
    a, b, plain = (
        fit(r, data, None, progress=False).history[0]["train_loss"] for r in (changed, changed, run)
    )
    return a == b and a != plain


def test_training_with_shifts_repeats_to_the_bit_and_differs_from_without(tiny_dataset, tiny_run):
    assert repeats_and_differs(tiny_dataset, tiny_run("segnet", epochs=1), shift_px=3)


def test_mix_batch_matches_a_loop_over_items():
    rng = np.random.default_rng(1)
    x = rng.random((5, 1, 4, 6)).astype(np.float32)
    y = rng.integers(0, 3, 5)
    perm = np.array([2, 0, 4, 1, 3])
    lam = 0.35
    xm, q = mix_batch(torch.from_numpy(x), torch.from_numpy(y), lam, torch.from_numpy(perm), 3)
    for i in range(5):
        np.testing.assert_allclose(xm[i].numpy(), lam * x[i] + (1 - lam) * x[perm[i]], rtol=1e-6)
        expected = np.zeros(3)
        expected[y[i]] += lam
        expected[y[perm[i]]] += 1 - lam
        np.testing.assert_allclose(q[i].numpy(), expected, rtol=1e-6)
    with pytest.raises(ValueError, match="label images"):
        mix_batch(
            torch.from_numpy(x),
            torch.zeros(5, 4, 6, dtype=torch.int64),
            lam,
            torch.from_numpy(perm),
            3,
        )


def test_mixup_weights_follow_beta_and_alpha_zero_is_the_identity():
    """Two items of classes 0 and 1: when mixup pairs each with the other, item 0's target puts
    lam on class 0; those lams must follow scipy's Beta(alpha, alpha)."""
    from scipy import stats

    torch.manual_seed(0)
    x, y = torch.stack([torch.zeros(1, 2, 2), torch.ones(1, 2, 2)]), torch.tensor([0, 1])
    lams = []
    for _ in range(4000):
        xm, q = mixup(x, y, 0.4, 2)
        if q[0, 1] > 0 or xm[0].max() > 0:  # paired with item 1 (lam = 1 exactly is improbable)
            lams.append(float(q[0, 0]))
            assert float(xm[0, 0, 0, 0]) == pytest.approx(1 - lams[-1], abs=1e-6)
    assert 1700 < len(lams) < 2300  # half the permutations swap the two
    assert stats.kstest(lams, stats.beta(0.4, 0.4).cdf).pvalue > 0.01
    assert mixup(x, y, 0.0, 2) == (x, y)
    with pytest.raises(ValueError, match="alpha"):
        mixup(x, y, -1.0, 2)


def test_mixup_is_checked_before_training_and_trains_reproducibly(tiny_dataset, tiny_run):
    from learn.train import RunConfig

    with pytest.raises(ConfigError, match=r"mixup_alpha.*classifier.*Fix"):
        dataclasses.replace(tiny_run("segnet"), mixup_alpha=0.2)
    with pytest.raises(ConfigError, match="mixup_alpha"):
        RunConfig(mixup_alpha=-0.5)
    assert repeats_and_differs(tiny_dataset, tiny_run("handsnet", epochs=1), mixup_alpha=0.4)
