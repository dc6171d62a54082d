"""PNG export and the `export` / `ingest` commands (through typer's CliRunner)."""

from __future__ import annotations

import numpy as np
import pytest
import typer
from PIL import Image
from typer.testing import CliRunner

from tactile import PALETTE, TactileMap
from tactile.cli.dataset import register
from tactile.dataset import DatasetWriter, export_png, open_dataset
from tactile.geometry.synthetic import cylinder_sector_layout

ACTIONS = ["grasp", "side touch"]


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    """6 samples: hands (subject 2, actions 0/1) and non-hands (instance 9), with label images."""
    folder = tmp_path_factory.mktemp("export") / "ds"
    layout, _ = cylinder_sector_layout(width_mm=50, length_mm=70, pitch_mm=8)
    tmap = TactileMap.build(layout)
    rng = np.random.default_rng(2)
    samples = []
    for i in range(6):
        p = rng.uniform(0, 100, layout.n_taxels) * (rng.uniform(size=layout.n_taxels) < 0.4)
        hand = i % 2 == 0
        labels = rng.integers(1, 7, layout.n_taxels).astype(np.uint8) * hand
        samples.append(
            {
                "raw": p.astype(np.uint16),
                "pressure_pa": p.astype(np.float32),
                "image": tmap.image(p),
                "taxel_label": labels,
                "label_image": tmap.label_image(p, labels)
                if hand
                else np.zeros(tmap.shape, np.uint8),
                "is_hand": np.uint8(hand),
                "action": np.int8(i % 4 // 2 if hand else -1),
                "subject_id": np.int32(2 if hand else -1),
                "instance_id": np.int32(-1 if hand else 9),
            }
        )
    w = DatasetWriter(
        folder,
        config={},
        part="p",
        generator_version="t",
        seed=0,
        tmap=tmap,
        layout=layout,
        attrs={"actions": ACTIONS},
    )
    w.write_chunk(0, samples)
    w.merge()
    return folder


def test_export_writes_the_supplementary_tree(tmp_path, dataset):
    written = export_png(dataset, tmp_path / "png")
    assert written == {"hand": 3, "labels": 3, "non_hand": 3}
    names = {p.relative_to(tmp_path / "png").as_posix() for p in (tmp_path / "png").rglob("*.png")}
    assert names == {
        "hand/000000_subject2_grasp.png",
        "hand/000002_subject2_side-touch.png",
        "hand/000004_subject2_grasp.png",
        "labels/000000_subject2_grasp.png",
        "labels/000002_subject2_side-touch.png",
        "labels/000004_subject2_grasp.png",
        "non_hand/000001_instance9.png",
        "non_hand/000003_instance9.png",
        "non_hand/000005_instance9.png",
    }
    ds = open_dataset(dataset)
    grey = np.asarray(Image.open(tmp_path / "png/non_hand/000003_instance9.png"))
    np.testing.assert_array_equal(grey, ds.image[3])
    rgb = np.asarray(Image.open(tmp_path / "png/labels/000002_subject2_side-touch.png"))
    np.testing.assert_array_equal(rgb, PALETTE[ds.label_image[2]])
    assert rgb.shape == (*ds.map.shape, 3) and ds.label_image[2].any()


def app() -> typer.Typer:
    a = typer.Typer()
    register(a)
    return a


def test_cli_export_and_ingest(tmp_path, dataset):
    runner = CliRunner()
    args = ["export", str(dataset), "--out", str(tmp_path / "png"), "--no-progress"]
    result = runner.invoke(app(), args)
    assert result.exit_code == 0, result.output
    assert "hand       3 PNG files" in result.output
    assert len(list((tmp_path / "png" / "hand").glob("*.png"))) == 3
    layout, _ = cylinder_sector_layout(width_mm=50, length_mm=70, pitch_mm=8)
    layout.save(tmp_path / "layout.csv")
    frames = np.random.default_rng(0).integers(0, 500, (4, layout.n_taxels))
    np.save(tmp_path / "frames.npy", frames)
    (tmp_path / "labels.csv").write_text("1\n0\n0\n1\n")
    args = [
        "ingest",
        str(tmp_path / "layout.csv"),
        str(tmp_path / "frames.npy"),
        "--out",
        str(tmp_path / "rec"),
        "--labels",
        str(tmp_path / "labels.csv"),
        "--step-mm",
        "2",
    ]
    result = runner.invoke(app(), args)
    assert result.exit_code == 0, result.output
    ds = open_dataset(tmp_path / "rec")
    assert ds.map.step_mm == 2.0 and list(ds.is_hand[:]) == [1, 0, 0, 1]


def test_cli_errors_and_units_in_help(tmp_path):
    runner = CliRunner()
    result = runner.invoke(app(), ["export", str(tmp_path / "none"), "--out", str(tmp_path)])
    assert result.exit_code == 2 and "no dataset at" in result.output
    args = ["ingest", "layout.csv", "frames.npy", "--out", str(tmp_path / "o"), "--step-mm", "0"]
    result = runner.invoke(app(), args)
    assert result.exit_code == 2 and "--step-mm 0.0 is out of range" in result.output
    result = runner.invoke(app(), ["ingest", "--help"], terminal_width=200)
    text = " ".join(result.output.replace("│", " ").split())
    for unit in ("mm/pixel", "counts/Pa", "raw 16-bit counts", "unitless"):
        assert unit in text


def test_export_without_class_labels_goes_to_unlabelled(tmp_path):
    from tactile.dataset import ingest_recording

    layout, _ = cylinder_sector_layout(width_mm=40, length_mm=60, pitch_mm=8)
    layout.save(tmp_path / "l.csv")
    frames = np.random.default_rng(1).integers(0, 900, (2, layout.n_taxels))
    np.save(tmp_path / "f.npy", frames)
    ingest_recording(tmp_path / "l.csv", tmp_path / "f.npy", tmp_path / "rec")
    assert export_png(tmp_path / "rec", tmp_path / "png") == {"unlabelled": 2}
    got = np.asarray(Image.open(tmp_path / "png/unlabelled/000001.png"))
    np.testing.assert_array_equal(got, TactileMap.build(layout).image(frames[1].astype(float)))
