"""Interleaved timing (`learn.fastpath.interleaved_cpu_ms`) against modules whose time per call
is set by a clock we control: the paths take turns round by round, each path's figure is the
least of its per-round medians, and `handskin evaluate` rows and reports say how they were
timed."""

from __future__ import annotations

import time

import pytest
import torch
from torch import nn

from learn.eval_report import _timing_rule, write_report
from learn.evaluate import evaluate_checkpoint
from learn.fastpath import interleaved_cpu_ms
from tactile.errors import ConfigError

SIZE = (4, 5)


class Sleeper(nn.Module):
    """Sleeps ``delays_s[k]`` seconds in every call of timing round ``k`` (a round is
    ``calls_per_round`` calls) and logs its name in ``log`` on each call."""

    def __init__(self, name: str, delays_s: list[float], calls_per_round: int, log: list[str]):
        super().__init__()
        self.name, self.delays_s, self.per_round, self.log = name, delays_s, calls_per_round, log
        self.calls = 0

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        self.log.append(self.name)
        time.sleep(self.delays_s[min(self.calls // self.per_round, len(self.delays_s) - 1)])
        self.calls += 1
        return x


def test_paths_take_turns_and_the_least_round_median_is_kept():
    log: list[str] = []
    warm, runs = 2, 5
    slow_then_fast = Sleeper("a", [0.012, 0.002, 0.006], warm + runs, log)  # ms: 12, 2, 6
    steady = Sleeper("b", [0.004], warm + runs, log)
    a_ms, none, b_ms = interleaved_cpu_ms(
        [slow_then_fast, None, steady], SIZE, threads=1, n_runs=runs, rounds=3, n_warmup=warm
    )
    assert none is None
    # Runs of one path come in blocks of warm + runs calls, alternating a, b, a, b, a, b.
    blocks = [log[i] for i in range(0, len(log), warm + runs)]
    assert blocks == ["a", "b"] * 3 and len(log) == 6 * (warm + runs)
    # sleep() never returns early and oversleeps by well under a millisecond here; the least
    # median is round 2's 2 ms, far from rounds 1 and 3 (12 and 6 ms).
    assert 2.0 <= a_ms < 3.5
    assert 4.0 <= b_ms < 5.5


def test_thread_count_restored_and_bad_options_refused():
    before = torch.get_num_threads()
    net = nn.Identity()
    interleaved_cpu_ms([net], SIZE, threads=1, n_runs=2, rounds=1)
    assert torch.get_num_threads() == before
    for kw in ({"rounds": 0}, {"n_runs": 0}, {"threads": 0}):
        with pytest.raises(ConfigError, match="fix the timing options"):
            interleaved_cpu_ms([net], SIZE, **{"n_runs": 2, "rounds": 1, "threads": 1, **kw})


def test_evaluate_rows_and_report_say_how_they_were_timed(checkpoints, tiny_dataset, tmp_path):
    row = evaluate_checkpoint(checkpoints["handsnet"], tiny_dataset, time_runs=3, time_rounds=2)
    assert (row["time_runs"], row["time_rounds"]) == (3, 2)
    assert all(row["ms_per_image"][k] > 0 for k in ("eval_mode", "prepared", "fast"))
    assert row["ms_per_image"]["compiled"] is None
    text = write_report([row], tmp_path / "r.md", "tiny").read_text()
    assert "median of 3 runs after 10 warm-up runs, the least over 2 rounds" in text
    old = {k: v for k, v in row.items() if k not in ("time_runs", "time_rounds")}
    assert _timing_rule([old]) == "median of 100 runs after 20 warm-up runs"  # earlier reports
    with pytest.raises(ConfigError, match="time rounds must be"):
        evaluate_checkpoint(checkpoints["handsnet"], tiny_dataset, time_rounds=0)


class SleepyPredictor:
    """A classical model stand-in for timing only: ``predict`` sleeps ``delays_s[k]`` in round
    ``k`` (``calls_per_round`` calls) and checks it gets one image at a time."""

    def __init__(self, delays_s: list[float], calls_per_round: int):
        self.delays_s, self.per_round, self.calls = delays_s, calls_per_round, 0

    def predict(self, images):
        assert images.shape[0] == 1
        time.sleep(self.delays_s[min(self.calls // self.per_round, len(self.delays_s) - 1)])
        self.calls += 1
        return images[:, 0, 0]


def test_classical_models_keep_the_least_round_median():
    import numpy as np

    from learn.classical import ms_per_image

    warm, runs = 2, 5
    model = SleepyPredictor([0.009, 0.003, 0.006], warm + runs)  # ms: 9, 3, 6
    ms = ms_per_image(model, np.zeros((4, 3, 3)), threads=1, n_runs=runs, rounds=3, n_warmup=warm)
    assert model.calls == 3 * (warm + runs)
    assert 3.0 <= ms < 4.5  # round 2's median, not the median over all rounds (6 ms)
    with pytest.raises(ConfigError, match="time rounds must be"):
        ms_per_image(model, np.zeros((4, 3, 3)), rounds=0)
