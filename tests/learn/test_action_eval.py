"""The action networks' evaluation: answers after k frames from those frames alone (a hand-computed
case), the chance levels, the mirror pairs' motion against the tiny set's own, and `handskin
train` / `handskin evaluate` on a tiny sequence set."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
import typer
from torch import nn
from typer.testing import CliRunner

from learn.cli import register
from learn.config import ModelConfig, RunConfig, TrainConfig
from learn.data.load import load_data
from learn.evaluate.actions import (
    chance_levels,
    mirror_cues,
    mirror_pairs,
    prefix,
    prefix_confusions,
    prefix_predictions,
    read_sequence_test,
)
from learn.infer.predict import load_predictor
from learn.train.loop import fit
from tactile.dataset.reader import DatasetReader
from tactile.errors import ConfigError
from tactile.geometry.synthetic import cylinder_sector_layout
from tactile.prints.motion import principal_angle

runner = CliRunner()


class LitFrames(nn.Module):
    """Answers class n: the number of frames of the sequence holding any pressure (at most 7)."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        n = (x.flatten(2).amax(2) > 0).sum(1).clamp_max(7)
        return nn.functional.one_hot(n, 8).float()


def test_answers_after_k_frames_see_those_frames_only():
    lengths, y = [3, 1, 5], torch.tensor([3, 1, 4])
    x = torch.zeros(3, 5, 1, 24, 24)
    for s, n in enumerate(lengths):
        x[s, :n] = 0.5
    pred = prefix_predictions(LitFrames(), x, batch_size=2)
    # by hand: after k frames a press of n frames shows min(k, n) of them
    assert pred.tolist() == [[1, 1, 1], [2, 1, 2], [3, 1, 3], [3, 1, 4], [3, 1, 5]]
    cms = prefix_confusions(pred, y, 8)
    right = [int(cm.trace()) for cm in cms]
    assert right == [1, 1, 2, 3, 2] and all(int(cm.sum()) == 3 for cm in cms)
    assert int(cms[0][3, 1]) == 1 and int(cms[4][4, 5]) == 1  # rows true, columns predicted
    assert torch.equal(prefix(x, 2)[2, 2:], torch.zeros(3, 1, 24, 24)) and prefix(x, 2)[2, 1].max()


def test_chance_levels_and_mirror_pairs():
    names = ("grasp", "twist_cw", "twist_ccw", "push_left", "push_right")
    chance = chance_levels(torch.tensor([4, 4, 4, 1, 0, 2]), names)
    assert chance == {"uniform": 0.2, "majority": 0.5, "majority_class": "push_right"}
    assert mirror_pairs(names) == [(1, 2), (3, 4)]
    assert mirror_pairs(("non_hand", "hand")) == []


@pytest.fixture(scope="module")
def app() -> typer.Typer:
    app = typer.Typer()
    register(app)
    return app


def test_train_and_evaluate_an_action_network(app, tiny_sequences, tmp_path):
    config = tmp_path / "run.toml"
    config.write_text(
        "threads = 1\nval_fraction = 0.2\n[model]\ninput_size = [32, 48]\nwidth = 0.25\n"
        "[train]\nepochs = 2\nbatch_size = 8\n"
    )
    out, md = tmp_path / "run", tmp_path / "report.md"
    args = ["train", str(tiny_sequences), "--arch", "action_3d", "--out", str(out)]
    res = runner.invoke(app, [*args, "--config", str(config), "--no-progress"])
    assert res.exit_code == 0, res.output
    assert json.loads((out / "test_metrics.json").read_text())["data"]["n_test"] == 8
    args = ["evaluate", str(tiny_sequences), str(out / "best.pt"), "--out", str(md)]
    res = runner.invoke(app, [*args, "--time-runs", "2", "--time-rounds", "1", "--no-progress"])
    assert res.exit_code == 0, res.output
    for png in ("report_actions_frames.png", "report_actions_confusion.png"):
        assert (tmp_path / png).stat().st_size > 1000, png
    (row,) = json.loads(md.with_suffix(".json").read_text())
    # the test split holds subjects 0 (right hand) and 5 (left): one press of each action
    assert row["chance"] == {"uniform": 0.125, "majority": 0.125, "majority_class": "grasp"}
    assert {h: v["n"] for h, v in row["hands"].items()} == {"right": 4, "left": 4}
    cm = np.asarray(row["cm"])
    assert cm.sum() == 8 and (cm.sum(1) == 1).all()
    assert row["prefix_accuracy"][-1] == row["metrics"]["accuracy"] == np.trace(cm) / 8
    assert row["frames"] == list(range(1, 13)) and row["ms_per_sequence"] > 0
    text = md.read_text()
    assert "chance 12.5 % (1 / 8)" in text and "| push_left / push_right | all | 2 |" in text


def test_image_commands_refuse_an_action_network(app, tiny_sequences, tmp_path):

    run = RunConfig(
        ModelConfig("action_3d", 8, width=0.25, input_size=(32, 48)),
        TrainConfig(epochs=1, batch_size=8),
        threads=1,
    )
    fit(run, load_data(tiny_sequences, run, progress=False), tmp_path / "r", progress=False)
    args = ["evaluate", str(tiny_sequences), str(tmp_path / "r" / "best.pt"), "--tta"]
    res = runner.invoke(app, [*args, "--out", str(tmp_path / "m.md")])
    assert res.exit_code == 2 and "action network" in res.output
    with pytest.raises(ConfigError, match="action network"):
        load_predictor(tmp_path / "r" / "best.pt")


def test_mirror_cues_measure_the_presses_own_motion(tiny_sequences):
    """Each tiny press moves a bar by ``SEQ_MOTION`` per frame; from the end of the load (frame 1)
    to the end of the hold (frame 3): a push left or right shifts it 2 x 3 mm x cos 30 deg
    across its axis, opposite ways, and a twist turns it opposite ways by as much as the same
    frames turn on the set's own flat coordinates (2 x 8 deg, as a 5 mm pitch samples it). A
    mirror image of the map flips both signs, so only their relation is fixed: in the bar's axes
    a push left moves against the sense a counter-clockwise twist turns."""
    run = RunConfig(ModelConfig("action_3d", 8, width=0.25, input_size=(32, 48)), TrainConfig())
    test = read_sequence_test(tiny_sequences, run, progress=False)
    cues = mirror_cues(tiny_sequences, test)
    assert set(cues) == {"grasp_twist_cw", "grasp_twist_ccw", "push_left", "push_right"}
    assert all(c["n"] == 1 for c in cues.values())  # one press of each in the test split
    left, right = cues["push_left"]["across_mm"][0], cues["push_right"]["across_mm"][0]
    cw, ccw = cues["grasp_twist_cw"]["turn_deg"][0], cues["grasp_twist_ccw"]["turn_deg"][0]
    assert abs(left) == pytest.approx(6 * np.cos(np.pi / 6), abs=1.5) and left * right < 0
    assert cw * ccw < 0 and left * ccw < 0
    # the turns against the same frames' pressures on the set's own flat coordinates (a 14 mm
    # bar sampled at a 5 mm pitch turns by 5-24 deg where the bar turns 16)
    _, flat_mm = cylinder_sector_layout(width_mm=60, length_mm=90, pitch_mm=5)
    with DatasetReader(tiny_sequences) as r:
        rows = {test.class_names[int(y)]: int(i) for y, i in zip(test.y, test.indices, strict=True)}
        for name in ("grasp_twist_cw", "grasp_twist_ccw"):
            p = r.pressure_from_raw(r.seq_raw[rows[name]][[1, 3]], np.array([0.2, 0.4]))
            turn = np.degrees(principal_angle(p[1], flat_mm) - principal_angle(p[0], flat_mm))
            assert abs(cues[name]["turn_deg"][0]) == pytest.approx(abs(turn), abs=1.5)
