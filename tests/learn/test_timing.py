"""Interleaved timing (`learn.infer.fastpath.interleaved_cpu_ms`) against modules whose time
per call is set on a clock the test controls: the paths take turns round by round, and each
path's figure is the least of its per-round medians."""

from __future__ import annotations

import types

import numpy as np
import pytest
import torch
from torch import nn

import learn.classical.run as classical_run
import learn.infer.fastpath as fastpath
from learn.classical.run import ms_per_image
from learn.evaluate.scoring import evaluate_checkpoint
from learn.infer.fastpath import interleaved_cpu_ms
from tactile.errors import ConfigError

SIZE = (4, 5)


class Clock:
    """A ``time`` module stand-in whose ``perf_counter`` only moves when told to."""

    def __init__(self) -> None:
        self.now = 0.0

    def perf_counter(self) -> float:
        return self.now


@pytest.fixture
def clock(monkeypatch) -> Clock:
    c = Clock()
    fake = types.SimpleNamespace(perf_counter=c.perf_counter)
    monkeypatch.setattr(fastpath, "time", fake)
    monkeypatch.setattr(classical_run, "time", fake)
    return c


class Ticker(nn.Module):
    """Takes ``delays_s[k]`` seconds of the clock per call in timing round ``k`` (a round is
    ``calls_per_round`` calls) and logs its name on each call."""

    def __init__(self, name, delays_s, calls_per_round, log, clock):
        super().__init__()
        self.name, self.delays_s, self.per_round = name, delays_s, calls_per_round
        self.log, self.clock, self.calls = log, clock, 0

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        self.log.append(self.name)
        self.clock.now += self.delays_s[min(self.calls // self.per_round, len(self.delays_s) - 1)]
        self.calls += 1
        return x


def test_paths_take_turns_and_the_least_round_median_is_kept(clock):
    log: list[str] = []
    warm, runs = 2, 5
    a = Ticker("a", [0.012, 0.002, 0.006], warm + runs, log, clock)  # ms: 12, 2, 6 by round
    b = Ticker("b", [0.004], warm + runs, log, clock)
    a_ms, none, b_ms = interleaved_cpu_ms(
        [a, None, b], SIZE, threads=1, n_runs=runs, rounds=3, n_warmup=warm
    )
    assert none is None
    blocks = [log[i] for i in range(0, len(log), warm + runs)]  # blocks of warm + runs calls
    assert blocks == ["a", "b"] * 3 and len(log) == 6 * (warm + runs)
    assert a_ms == pytest.approx(2.0) and b_ms == pytest.approx(4.0)  # round 2's, not 6 ms


def test_thread_count_restored_and_bad_options_refused():
    before = torch.get_num_threads()
    net = nn.Identity()
    interleaved_cpu_ms([net], SIZE, threads=1, n_runs=2, rounds=1)
    assert torch.get_num_threads() == before
    for kw in ({"rounds": 0}, {"n_runs": 0}, {"threads": 0}):
        with pytest.raises(ConfigError, match="fix the timing options"):
            interleaved_cpu_ms([net], SIZE, **{"n_runs": 2, "rounds": 1, "threads": 1, **kw})


def test_evaluate_rows_say_how_they_were_timed(checkpoints, tiny_dataset):
    row = evaluate_checkpoint(checkpoints["handsnet"], tiny_dataset, time_runs=3, time_rounds=2)
    assert (row["time_runs"], row["time_rounds"]) == (3, 2)
    assert all(row["ms_per_image"][k] > 0 for k in ("eval_mode", "prepared", "fast"))
    with pytest.raises(ConfigError, match="time rounds must be"):
        evaluate_checkpoint(checkpoints["handsnet"], tiny_dataset, time_rounds=0)


class TickingPredictor:
    """A classical model stand-in for timing only: ``predict`` takes ``delays_s[k]`` of the
    clock in round ``k`` (``calls_per_round`` calls) and checks it gets one image at a time."""

    def __init__(self, delays_s, calls_per_round, clock):
        self.delays_s, self.per_round, self.clock, self.calls = delays_s, calls_per_round, clock, 0

    def predict(self, images):
        assert images.shape[0] == 1
        self.clock.now += self.delays_s[min(self.calls // self.per_round, len(self.delays_s) - 1)]
        self.calls += 1
        return images[:, 0, 0]


def test_classical_models_keep_the_least_round_median(clock):
    warm, runs = 2, 5
    model = TickingPredictor([0.009, 0.003, 0.006], warm + runs, clock)  # ms: 9, 3, 6
    ms = ms_per_image(model, np.zeros((4, 3, 3)), threads=1, n_runs=runs, rounds=3, n_warmup=warm)
    assert model.calls == 3 * (warm + runs)
    assert ms == pytest.approx(3.0)  # round 2's median, not the median over all rounds (6 ms)
    with pytest.raises(ConfigError, match="time rounds must be"):
        ms_per_image(model, np.zeros((4, 3, 3)), rounds=0)


def test_time_per_image_is_the_median_after_warm_up_and_leaves_eval_mode(clock):
    """Calls of 5, 1, 4, 2, 3 ms after two slow warm-up calls: the median is 3 ms."""
    delays = iter([0.5, 0.5, 0.005, 0.001, 0.004, 0.002, 0.003])

    class Net(nn.Module):
        def forward(self, x):
            clock.now += next(delays)
            return x

    net = Net().train()
    seconds = fastpath.time_per_image(net, SIZE, "cpu", n_warmup=2, n_runs=5)
    assert seconds == pytest.approx(0.003) and not net.training
