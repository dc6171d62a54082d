"""Weight averaging (learn.averaging, TrainConfig.ema_decay): the average against the closed-form
recursion over recorded weights, and what ``fit`` validates, saves and resumes with it."""

from __future__ import annotations

import pytest
import torch
from torch import nn

from learn.averaging import make_ema
from learn.checkpoint import load_checkpoint
from learn.config import TrainConfig
from learn.evaluate import evaluate_tensors
from learn.train import fit, load_data, replace_train
from tactile.errors import ConfigError


@pytest.fixture(autouse=True)
def _one_thread():
    torch.set_num_threads(1)


def _train(model: nn.Module, opt, steps: int, scale: float = 1.0, seed: int = 0):
    """Yield after each of ``steps`` SGD steps on random (8, 3) inputs times ``scale``."""
    gen = torch.Generator().manual_seed(seed)
    for _ in range(steps):
        loss = model(scale * torch.randn(8, 3, generator=gen)).square().mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        yield


def test_average_follows_the_warmed_up_recursion_over_every_step_weights_and_buffers():
    """Against ``w_bar <- d w_bar + (1 - d) w_t``, ``d = min(decay, (1 + t) / (10 + t))`` for
    update t = 0, 1, ... after the first step's copy (tf.train.ExponentialMovingAverage's
    num_updates form), on every float parameter and buffer; integer buffers are the model's."""
    torch.manual_seed(0)
    model = nn.Sequential(nn.Linear(3, 4), nn.BatchNorm1d(4), nn.ReLU(), nn.Linear(4, 1))
    opt = torch.optim.SGD(model.parameters(), lr=0.05, momentum=0.9)
    decay = 0.6  # reached at t = 13: both regimes within 30 steps
    ema = make_ema(model, opt, decay)
    want: dict[str, torch.Tensor] = {}
    for t, _ in enumerate(_train(model, opt, 30), start=-1):
        now = {k: v.clone() for k, v in model.state_dict().items() if v.is_floating_point()}
        d = min(decay, (1 + t) / (10 + t)) if t >= 0 else 0.0
        want = {k: d * want[k] + (1 - d) * v for k, v in now.items()} if want else now
    got = ema.module.state_dict()
    for k, v in want.items():
        torch.testing.assert_close(got[k], v, rtol=1e-5, atol=1e-6, msg=k)
    assert "1.running_var" in want and int(ema.n_averaged) == 30
    assert torch.equal(got["1.num_batches_tracked"], model.state_dict()["1.num_batches_tracked"])
    assert not torch.equal(got["0.weight"], model.state_dict()["0.weight"])


def test_the_average_forgets_the_initial_batch_norm_statistics():
    """Inputs 1,000 times smaller than BatchNorm's initial running variance (1) assumes: after 300
    steps at decay 0.998 the averaged variances are the trained ones' size. Without the warm-up
    the initial 1 would still weigh 0.998 ** 300 = 0.55, ~10,000 times the true variance."""
    torch.manual_seed(1)
    model = nn.Sequential(nn.Linear(3, 4), nn.BatchNorm1d(4), nn.ReLU(), nn.Linear(4, 1))
    opt = torch.optim.SGD(model.parameters(), lr=0.01)
    ema = make_ema(model, opt, 0.998)
    for _ in _train(model, opt, 300, scale=1e-3, seed=1):
        pass
    ratio = ema.module[1].running_var / model[1].running_var
    assert torch.all((ratio > 0.5) & (ratio < 2.0)), ratio


def test_decay_zero_is_off_and_a_decay_out_of_range_is_refused():
    model = nn.Linear(2, 1)
    assert make_ema(model, torch.optim.SGD(model.parameters(), lr=0.1), 0.0) is None
    with pytest.raises(ConfigError, match=r"ema_decay must be in \[0, 1\).*Fix"):
        TrainConfig(ema_decay=1.0)


def _average(ckpt: dict) -> dict[str, torch.Tensor]:
    """The averaged network's state dict from a last.pt's ``ema`` (an AveragedModel's)."""
    return {k.removeprefix("module."): v for k, v in ckpt["ema"].items() if k != "n_averaged"}


def test_fit_validates_keeps_and_resumes_the_average(tiny_dataset, tiny_run, tmp_path):
    run = replace_train(tiny_run("handsnet", epochs=2), ema_decay=0.9)
    data = load_data(tiny_dataset, run)
    full = fit(run, data, tmp_path / "full", progress=False)
    fit(run, data, tmp_path / "cut", progress=False, stop_after_epoch=1)
    after = {1: _average(load_checkpoint(tmp_path / "cut" / "last.pt"))}  # epoch -> average
    resumed = fit(run, data, tmp_path / "cut", resume=True, progress=False)
    last = load_checkpoint(tmp_path / "full" / "last.pt")
    after[2] = _average(last)
    assert after[2].keys() == last["model"].keys()
    assert any(not torch.equal(after[2][k], v) for k, v in last["model"].items())
    best = load_checkpoint(tmp_path / "full" / "best.pt")  # the average at the best epoch
    for k, v in best["model"].items():
        assert torch.equal(v, after[best["epoch"]][k]), k
    # the history's val metric is the average's: the returned model scores it again
    val = evaluate_tensors(full.model, data.val, 2).metrics["accuracy"]
    assert val == full.history[best["epoch"] - 1]["val_metric"] == full.best_metric
    # stopped after epoch 1 and resumed, the run is the uninterrupted one
    assert [h["val_metric"] for h in resumed.history] == [h["val_metric"] for h in full.history]
    cut = load_checkpoint(tmp_path / "cut" / "last.pt")
    for k, v in last["ema"].items():
        assert torch.equal(v, cut["ema"][k]), k
