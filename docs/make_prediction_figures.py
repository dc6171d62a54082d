"""Regenerate the prediction pictures of docs/viewing.md from trained models.

    PYTHONPATH=. python docs/make_prediction_figures.py --data out/forearm \
        --classifier runs/handsnet/best.pt --segmenter runs/segnet/best.pt [--index I] [--out docs]

writes, for one hand sample of the dataset's test split (``--index``, default: the test-split
hand sample whose label image shows the most hand parts, the smallest index on ties):

- ``prediction.png``: tactile image | true labels | predicted segmentation | errors in red
  (the paper's Figs. 12-13), the classifier's decision as the title;
- ``prediction_parts.png``: per hand part, pressed taxels and their mean pressure (kPa), true
  and predicted (back-projected through the map), as the paper's Fig. 18;
- ``prediction_3d.png``: the predicted per-taxel labels on the 3D part with the contactor in
  place (the dataset must be synthetic: its sample is re-simulated to place the hand).

The same pictures come from the two commands that docs/viewing.md shows (`handskin predict
--png ... --save-labels L.npy`, then `handskin view DATASET --sample I --color prediction --pred
L.npy --png ...`); this script calls the same functions. Nothing here is random.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from tactile.errors import DataError, HandskinError

DOCS = Path(__file__).resolve().parent
SIZE_PX = (1200, 520)  # (width, height) of the 3D view, pixels (as handskin view's default)


def pick_index(data: Path) -> int:
    """The test-split hand sample whose label image holds the most classes (smallest on ties)."""
    from tactile.dataset import open_dataset

    with open_dataset(data) as ds:
        test = np.sort(ds.splits["test"])
        hands = test[np.asarray(ds.is_hand[:])[test] > 0]
        if not len(hands):
            raise DataError(f"{data}: no hand sample in the test split; give --index")
        n_parts = [len(np.unique(ds.label_image[int(i)])) for i in hands]
    return int(hands[int(np.argmax(n_parts))])


def render_3d(data: Path, index: int, taxel_labels: np.ndarray, path: Path) -> Path:
    """The predicted per-taxel labels on the re-simulated 3D scene of sample ``index``."""
    from PIL import Image

    from sim.view import render_scene
    from sim.view_cli import from_dataset

    scene = from_dataset(data, index)[0]
    if scene is None:
        raise DataError(f"{data} cannot be re-simulated (not a synthetic dataset): no 3D view")
    view = render_scene(scene, "prediction", taxel_labels.astype(np.int64), size_px=SIZE_PX)
    Image.fromarray(view).save(path)
    return path


def main(
    data: Annotated[Path, typer.Option(help="Synthetic dataset folder (dataset.h5).")],
    classifier: Annotated[Path, typer.Option(help="Classifier checkpoint (.pt file).")],
    segmenter: Annotated[Path, typer.Option(help="Segmenter checkpoint (.pt file).")],
    index: Annotated[
        int | None,
        typer.Option(help="Sample index (count, 0-based); default: picked from the test split."),
    ] = None,
    out: Annotated[Path, typer.Option(help="Folder of the PNG files.")] = DOCS,
) -> None:
    """Write prediction.png, prediction_parts.png and prediction_3d.png into OUT."""
    from learn.predict import load_predictor, predict_sample, read_sample, save_figures

    try:
        for path in (classifier, segmenter):
            if not path.is_file():
                raise DataError(f"no checkpoint at {path}. Fix: a .pt file from handskin train")
        index = pick_index(data) if index is None else index
        sample = read_sample(data, index)
        pred = predict_sample(sample, load_predictor(classifier), load_predictor(segmenter))
        out.mkdir(parents=True, exist_ok=True)
        name = f"predicted ({segmenter.parent.name})"
        written = save_figures(pred, out / "prediction.png", name)
        written.append(render_3d(data, index, pred.taxel_labels, out / "prediction_3d.png"))
    except HandskinError as err:
        typer.echo(f"error: {err}", err=True)
        raise typer.Exit(2) from err
    typer.echo(f"sample {index}: {pred.class_name} (p = {pred.probability:.3f})")
    for path in written:
        typer.echo(f"written: {path}")


if __name__ == "__main__":
    typer.run(main)
