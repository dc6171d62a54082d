"""3D views render headless (pyvista off-screen), with the contactor replayed in place, and the
`handskin view` command writes non-blank pictures of the expected size."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import typer
from PIL import Image
from typer.testing import CliRunner

from sim.cli.view import register, simulated
from sim.generate.tiny import tiny_config
from sim.view.render import geom_mesh, render_scene
from sim.view.scenes import GeomShape, simulate_scene

SIZE_PX = (320, 160)  # (width, height) of the test renders, pixels
CAPTION_PX = 20  # rows of the captions at the top of a 160-pixel-high render


def assert_not_blank(rgb: np.ndarray, min_fraction: float = 0.05) -> None:
    """Pixels vary and a fair share differs from the background (the corner pixel)."""
    assert rgb.std() > 10
    assert np.mean(np.any(rgb != rgb[0, 0], axis=-1)) > min_fraction


@pytest.fixture(scope="module")
def hand():
    """Sample 2 of the tiny preset (plate part): a hand, simulated and replayed."""
    return simulate_scene(tiny_config(n=8, seed=0), 2)


def test_replayed_hand_has_its_parts_near_the_skin(hand):
    scene = hand.scene
    assert scene.kind == "hand"
    assert {g.label for g in scene.geoms} == {1, 2, 3, 4, 5, 6}
    centres = np.array([g.pos_m for g in scene.geoms])
    # the plate's skin is its top face z = 0; pressed geoms sit within a few cm of it
    assert np.abs(centres[:, 2]).min() < 0.02
    assert (scene.pressure_pa > 0).any()


@pytest.mark.parametrize("color", ["pressure", "label", "prediction"])
def test_render_scene_is_not_blank(hand, color):
    predicted = np.where(hand.scene.labels > 0, 6, 0) if color == "prediction" else None
    rgb = render_scene(hand.scene, color, predicted, size_px=SIZE_PX)
    assert rgb.shape == (SIZE_PX[1], SIZE_PX[0], 3) and rgb.dtype == np.uint8
    assert_not_blank(rgb, 0.2)


def test_render_scene_rejects_prediction_without_labels(hand):
    with pytest.raises(ValueError, match="predicted"):
        render_scene(hand.scene, "prediction", size_px=SIZE_PX)


@pytest.mark.parametrize("kind", ["sphere", "capsule", "cylinder", "box", "ellipsoid"])
def test_geom_mesh_is_placed_and_sized(kind):
    rot = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])
    g = GeomShape(kind, np.array([0.01, 0.02, 0.03]), np.array([0.1, 0.0, 0.0]), rot, 0)
    mesh = geom_mesh(g)
    assert np.allclose(mesh.center, g.pos_m, atol=2e-3)
    assert mesh.n_cells > 0


def test_view_command_writes_pictures(tmp_path: Path):
    app = typer.Typer()
    register(app)
    app.callback()(lambda: None)
    args = [
        "view",
        "--part",
        "plate",
        "--sample",
        "2",
        "--color",
        "label",
        "--width",
        "320",
        "--height",
        "160",
        "--png",
        str(tmp_path / "v.png"),
        "--panel",
        str(tmp_path / "p.png"),
        "--sequence",
        str(tmp_path / "s.gif"),
    ]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    view = np.asarray(Image.open(tmp_path / "v.png").convert("RGB"))
    assert view.shape == (160, 320, 3)
    assert_not_blank(view, 0.2)
    assert_not_blank(np.asarray(Image.open(tmp_path / "p.png").convert("RGB")), 0.1)
    assert Image.open(tmp_path / "s.gif").n_frames > 3


def test_view_command_explains_a_missing_prediction(tmp_path: Path):
    app = typer.Typer()
    register(app)
    app.callback()(lambda: None)
    result = CliRunner().invoke(
        app, ["view", "--part", "plate", "--color", "prediction", "--png", str(tmp_path / "v.png")]
    )
    assert result.exit_code == 2 and "--pred" in result.output


def _view(tmp_path: Path, name: str, *extra: str) -> np.ndarray:
    """`handskin view --part plate --sample 2` (a hand) with ``extra`` options: the 3D picture."""
    app = typer.Typer()
    register(app)
    app.callback()(lambda: None)
    png = tmp_path / f"{name}.png"
    result = CliRunner().invoke(
        app,
        [
            "view",
            "--part",
            "plate",
            "--sample",
            "2",
            "--width",
            "320",
            "--height",
            "160",
            "--png",
            str(png),
            *extra,
        ],
    )
    assert result.exit_code == 0, result.output
    return np.asarray(Image.open(png).convert("RGB")).astype(int)


def test_view_draws_per_taxel_labels_saved_by_predict(tmp_path: Path):
    """The hand-off of `handskin predict ... --out FILE.npy`: (N,) uint8 class ids colour
    the skin. Labels equal to the truth draw what --color label draws (up to the caption);
    another labelling draws another skin."""
    labels = simulated("plate", 0, 2, False)[0].labels  # the sample the command draws
    assert labels.any()
    np.save(tmp_path / "same.npy", labels.astype(np.uint8))
    np.save(tmp_path / "other.npy", np.where(labels > 0, 0, 6).astype(np.uint8))
    truth = _view(tmp_path, "truth", "--color", "label")
    same = _view(tmp_path, "same", "--color", "prediction", "--pred", str(tmp_path / "same.npy"))
    other = _view(tmp_path, "other", "--color", "prediction", "--pred", str(tmp_path / "other.npy"))
    below = slice(CAPTION_PX, None)  # the captions differ: "skin: label" / "skin: prediction"
    differs = lambda a, b: np.mean(np.any(np.abs(a[below] - b[below]) > 8, axis=-1))  # noqa: E731
    assert differs(truth, same) == 0.0
    assert differs(truth, other) > 0.05


def test_view_explains_a_missing_labels_file(tmp_path: Path):
    app = typer.Typer()
    register(app)
    app.callback()(lambda: None)
    result = CliRunner().invoke(
        app,
        [
            "view",
            "--part",
            "plate",
            "--color",
            "prediction",
            "--pred",
            str(tmp_path / "none.npy"),
            "--png",
            str(tmp_path / "v.png"),
        ],
    )
    text = " ".join(result.output.split())
    assert result.exit_code == 2 and "--pred" in text and "--out FILE.npy" in text, text


def test_view_command_names_a_bad_sample(tmp_path: Path):
    app = typer.Typer()
    register(app)
    app.callback()(lambda: None)
    args = ["view", "--part", "plate", "--sample", "-1", "--png", str(tmp_path / "v.png")]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 2 and "--sample -1 out of range" in result.output
    assert not (tmp_path / "v.png").exists()


def test_the_command_offers_the_renderers_colours():
    """`sim.cli.view` spells the colour choices out (importing `sim.view.render` loads pyvista)."""
    from sim.cli import view as view_cli
    from sim.view import render

    assert view_cli.COLORS == render.COLORS
