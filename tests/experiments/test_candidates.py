"""`handskin experiment candidates`: the choice of the default against its stated rule, the
arguments in words, and one run on the tiny set whose scores equal the scorers' own."""

from __future__ import annotations

import json

import numpy as np
import pytest
from PIL import Image

from experiments.candidates import Candidate, choose, parse_candidate, run_candidates
from learn.evaluate.real import evaluate_real
from tactile.dataset import open_dataset
from tactile.errors import ConfigError, DataError
from tactile.images.labels import CLASS_NAMES
from tactile.prints.shapes import boxes_of_labels


def test_the_default_is_the_fastest_within_the_margin():
    rows = [
        {"name": "big", "median_ms": 12.0, "real_localised": 0.70},
        {"name": "small", "median_ms": 2.0, "real_localised": 0.68},  # 2 points below
        {"name": "tiny", "median_ms": 1.0, "real_localised": 0.60},  # 10 points below
    ]
    assert choose(rows, 3.0) == "small"
    assert choose(rows, 1.0) == "big"
    assert choose(rows, 10.0) == "tiny"


def test_candidate_arguments_in_words(tmp_path):
    net = tmp_path / "n.pt"
    net.write_bytes(b"")
    assert parse_candidate(f"A=  {net}") == Candidate("A", (net,))
    with pytest.raises(ConfigError, match=r"NAME=NETWORK\.pt or NAME=CLASSIFIER\.pt,SEGMENTER"):
        parse_candidate(str(net))
    with pytest.raises(DataError, match="no checkpoint at"):
        parse_candidate(f"A={tmp_path / 'missing.pt'}")


@pytest.fixture(scope="module")
def real_folder(tiny_dataset, tmp_path_factory):
    """The tiny set's hand prints as a box folder (each part boxed tightly)."""
    root = tmp_path_factory.mktemp("real")
    (root / "images").mkdir()
    (root / "labels").mkdir()
    with open_dataset(tiny_dataset) as ds:
        for i in np.flatnonzero(ds.is_hand[:] == 1)[:6]:
            image = np.asarray(ds.image[i])
            Image.fromarray(image).save(root / "images" / f"{i}.png")
            h, w = image.shape
            lines = [
                f"{p - 1} {(c0 + c1) / 2 / w} {(r0 + r1) / 2 / h} {(c1 - c0) / w} {(r1 - r0) / h}"
                for p, r0, r1, c0, c1 in boxes_of_labels(np.asarray(ds.label_image[i]), image)
            ]
            (root / "labels" / f"{i}.txt").write_text("\n".join(lines) + "\n")
    (root / "data.yaml").write_text(f"names: {list(CLASS_NAMES[1:])}\n")
    return root


def test_a_run_reports_the_scorers_numbers(checkpoints, tiny_dataset, real_folder, tmp_path):
    pair = Candidate("pair", (checkpoints["handsnet"], checkpoints["segnet"]))
    out = tmp_path / "c"
    result = run_candidates([pair], tiny_dataset, [real_folder], out, frames=10, margin=3.0)
    (row,) = result["rows"]
    rows, _ = evaluate_real(real_folder, list(pair.networks), tiny_dataset)
    assert row["real"][str(real_folder)]["localised"] == rows[1]["localised"]
    assert row["real"][str(real_folder)]["hand_recall"] == rows[0]["hand_recall"]
    assert row["median_ms"] > 0 and result["default"] == "pair"
    assert json.loads((out / "results.json").read_text())["rows"][0]["name"] == "pair"
    assert "pair (default)" in (out / "report.md").read_text()
    assert (out / "latency_accuracy.png").is_file()
