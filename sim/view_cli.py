"""`handskin view`: a 3D view, the Fig. 1 panel and the 10 Hz sequence of one sample.

The sample comes from a dataset (``DATASET --sample I``: a synthetic dataset is re-simulated from
its stored configuration to place the contactor, a real one is drawn without it) or is simulated
now (``--seed S --index I``). `register(app)` adds the command (wired in handskin/cli.py).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from tactile.errors import ConfigError, DataError, HandskinError

COLORS = ("pressure", "label", "prediction")  # as sim.view.COLORS (not imported: keeps --help fast)


def _fail(err: Exception) -> typer.Exit:
    typer.echo(f"error: {err}", err=True)
    return typer.Exit(2)


def has_display() -> bool:
    """Whether an interactive window can open (X11 or Wayland display set)."""
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def load_predicted(path: Path, tmap, n_taxels: int) -> tuple[np.ndarray, np.ndarray | None]:
    """(per-taxel classes (N,), pixel segmentation (H, W) or None) from a .npy of (N,) taxel
    labels (as ``handskin predict --save-labels`` writes) or of an (H, W) segmentation
    (back-projected with `tactile.labels.backproject`)."""
    from tactile.labels import backproject, check_labels

    path = Path(path)
    if not path.is_file():
        raise DataError(
            f"no predicted labels at {path}. Fix: write them with handskin predict "
            "--data DATASET --index I --segmenter CKPT --save-labels FILE.npy"
        )
    try:
        arr = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as err:
        raise DataError(f"{path}: not a .npy array of class ids ({err})") from err
    if arr.shape == tmap.shape:
        return backproject(tmap, arr.astype(np.int64)).astype(np.int64), arr.astype(np.int64)
    if arr.shape == (n_taxels,):
        return check_labels(arr.astype(np.int64), n_taxels), None
    raise DataError(
        f"{path}: shape {arr.shape}; expected ({n_taxels},) taxel labels or "
        f"{tmap.shape} pixel classes"
    )


def from_dataset(path: Path, index: int):
    """(ViewScene or None, tmap, sample dict, sequence images or None) of dataset sample ``index``.

    A synthetic dataset (attrs ``config``) is re-simulated to place the contactor; a real one
    (or another part) gives no 3D scene."""
    from tactile.dataset import open_dataset
    from tactile.figures import common_scale_images

    with open_dataset(path) as ds:
        if not 0 <= index < len(ds):
            raise DataError(f"--sample {index} out of range; the dataset has {len(ds)} samples")
        sample, tmap, config = ds[index], ds.map, ds.attrs.get("config")
        seq = None
        if "seq_raw" in ds.fields:
            from sim.episode import FRAME_DT_S

            raw = sample["seq_raw"][: int(sample["seq_length"])]
            times_s = (np.arange(len(raw)) + 1) * FRAME_DT_S  # frame k at (k + 1) / 10 Hz
            seq = common_scale_images(tmap, ds.pressure_from_raw(raw, times_s))
    if not isinstance(config, dict):
        return None, tmap, sample, seq
    from sim.gen_config import GenerateConfig
    from sim.view import simulate_scene
    from tactile.config import from_dict

    try:
        cfg = from_dict(GenerateConfig, config)
    except ConfigError:  # not a synthetic dataset's configuration (e.g. an ingested recording)
        return None, tmap, sample, seq
    return simulate_scene(cfg, index).scene, tmap, sample, seq


def simulated(part: str, seed: int, index: int, sequence: bool):
    """(ViewScene, tmap, sample dict, sequence images or None) of sample ``index`` simulated now."""
    from sim.gen_config import GenerateConfig
    from sim.view import sequence_pressure, simulate_scene
    from tactile.figures import common_scale_images

    cfg = GenerateConfig(part=part, seed=seed, n=index + 1, keep_sequences=sequence)
    sim = simulate_scene(cfg, index)
    seq = None
    if sequence:
        p = sequence_pressure(sim.ctx, sim.sample["seq_raw"], int(sim.sample["seq_length"]))
        seq = common_scale_images(sim.ctx.tmap, p)
    return sim.scene, sim.ctx.tmap, sim.sample, seq


def write_outputs(scene, tmap, sample, seq, opts: dict) -> list[Path]:
    """Write the requested PNG / GIF files; returns their paths."""
    from PIL import Image

    from sim.view import render_scene
    from tactile.figures import sample_panel, save_figure, save_sequence_gif, sequence_strip

    out, view = [], None
    predicted = opts["predicted"]
    if scene is not None and (opts["png"] or opts["panel"] or opts["interactive"]):
        view = render_scene(
            scene,
            opts["color"],
            predicted,
            size_px=opts["size_px"],
            interactive=opts["interactive"],
        )
    if opts["png"] and view is None:
        raise DataError(
            "no 3D scene for this sample: the dataset is not a synthetic one whose "
            "configuration can be re-simulated. Fix: write --panel or "
            "--prediction-png instead of --png"
        )
    if opts["png"]:
        opts["png"].parent.mkdir(parents=True, exist_ok=True)
        Image.fromarray(view).save(opts["png"])
        out.append(opts["png"])
    if opts["panel"]:
        title = scene.title if scene is not None else ""
        fig = sample_panel(
            view,
            tmap,
            sample["image"],
            sample.get("label_image"),
            np.asarray(sample["pressure_pa"], dtype=float),
            title,
        )
        out.append(save_figure(fig, opts["panel"], dpi=90))
    if opts["prediction_png"]:
        out.extend(
            prediction_outputs(
                tmap,
                sample,
                predicted,
                opts["pred_pixels"],
                opts["prediction_png"],
                opts["pred_name"],
            )
        )
    if opts["sequence"]:
        if seq is None:
            raise DataError("no 10 Hz sequence for this sample: the dataset has no seq_raw")
        if opts["sequence"].suffix.lower() == ".gif":
            out.append(save_sequence_gif(opts["sequence"], seq, scale=2))
        else:
            out.append(save_figure(sequence_strip(seq), opts["sequence"]))
    return out


def prediction_outputs(
    tmap, sample: dict, predicted, pred_pixels, png: Path, name: str = "predicted"
) -> list[Path]:
    """Figs. 12-13 (image, true, predicted, errors) at ``png`` and Fig. 18's per-part bars
    (true vs predicted taxel labels) beside it (``<stem>_parts.png``)."""
    from tactile.figures import part_bars_figure, prediction_figure, save_figure

    if pred_pixels is None:
        raise DataError(
            "--prediction-png needs --pred as an (H, W) pixel segmentation; for "
            "(N,) taxel labels, handskin predict --png draws these figures"
        )
    pressure = np.asarray(sample["pressure_pa"], dtype=float)
    fig = prediction_figure(sample["image"], sample["label_image"], pred_pixels, pred_name=name)
    bars = part_bars_figure(
        sample["taxel_label"],
        pressure,
        pred_labels=predicted,
        threshold_pa=0.0,
        title=f"hatched: {name}",
    )
    return [
        save_figure(fig, png, dpi=90),
        save_figure(bars, png.with_name(f"{png.stem}_parts.png"), dpi=90),
    ]


def view_command(
    dataset: Annotated[
        Path | None,
        typer.Argument(
            help="Dataset folder (or its dataset.h5); omit to simulate a sample with "
            "--seed/--index."
        ),
    ] = None,
    sample: Annotated[int, typer.Option(help="Sample index in DATASET (count, 0-based).")] = 0,
    part: Annotated[
        str,
        typer.Option(
            help="Built-in part for a simulated sample (name: forearm, forearm_8mm, forearm_x2, "
            "forearm_x4, end_effector, plate; no unit)."
        ),
    ] = "forearm",
    seed: Annotated[int, typer.Option(help="Dataset seed of the simulated sample (integer).")] = 0,
    index: Annotated[
        int,
        typer.Option(
            help="Index of the simulated sample (count, 0-based; samples 2, 4, 6, ... are hands "
            "with the default hand fraction)."
        ),
    ] = 2,
    color: Annotated[
        str,
        typer.Option(
            help="Taxel colours: pressure (kPa colour bar), label (class palette) or prediction "
            "(classes read from --pred); no unit."
        ),
    ] = "pressure",
    pred: Annotated[
        Path | None,
        typer.Option(
            help="Predicted classes for --color prediction: .npy of (N,) taxel class ids or an "
            "(H, W) pixel segmentation (class ids 0..6, no unit)."
        ),
    ] = None,
    png: Annotated[
        Path | None, typer.Option(help="Write the 3D view (PNG, --width x --height pixels).")
    ] = None,
    panel: Annotated[
        Path | None,
        typer.Option(
            help="Write the Fig. 1 panel: 3D view, map (mm), tactile image, labels (PNG, 90 dpi)."
        ),
    ] = None,
    sequence: Annotated[
        Path | None,
        typer.Option(
            help="Write the 10 Hz frames on one intensity scale: .gif animation (real time, 2 px "
            "per mm) or .png strip."
        ),
    ] = None,
    pred_name: Annotated[
        str,
        typer.Option(
            help="Caption of the predicted labels in the figures (text, no unit), e.g. a model "
            "name or 'ablated ground truth'."
        ),
    ] = "predicted",
    prediction_png: Annotated[
        Path | None,
        typer.Option(
            help="With --pred (H, W): write image / true / predicted / errors in red (PNG, 90 dpi) "
            "and the per-part mean pressure (kPa) and taxel count bars beside it."
        ),
    ] = None,
    width: Annotated[int, typer.Option(help="3D view width, pixels.")] = 1200,
    height: Annotated[int, typer.Option(help="3D view height, pixels.")] = 520,
    interactive: Annotated[
        bool, typer.Option(help="Open an interactive 3D window (needs a display; no unit).")
    ] = False,
) -> None:
    """Draw one sample: 3D view (part, taxels, contactor in place), Fig. 1 panel, sequence."""
    try:
        if color not in COLORS:
            raise ConfigError(f"--color {color!r} unknown; choose one of {', '.join(COLORS)}")
        if color == "prediction" and pred is None:
            raise ConfigError("--color prediction needs --pred FILE.npy (predicted classes)")
        if interactive and not has_display():
            raise ConfigError("--interactive needs a display (DISPLAY unset); write --png instead")
        if not (png or panel or sequence or interactive or prediction_png):
            png = Path("out/view.png")
        if dataset is not None:
            scene, tmap, smp, seq = from_dataset(dataset, sample)
        else:
            scene, tmap, smp, seq = simulated(part, seed, index, sequence is not None)
        predicted, pred_pixels = load_predicted(pred, tmap, tmap.n_taxels) if pred else (None, None)
        opts = {
            "png": png,
            "panel": panel,
            "sequence": sequence,
            "color": color,
            "predicted": predicted,
            "pred_pixels": pred_pixels,
            "size_px": (width, height),
            "interactive": interactive,
            "prediction_png": prediction_png,
            "pred_name": pred_name,
        }
        written = write_outputs(scene, tmap, smp, seq, opts)
    except (HandskinError, KeyError, ValueError) as err:
        raise _fail(err) from err
    for path in written:
        typer.echo(f"written: {path}")


def register(app: typer.Typer) -> None:
    """Add `view` to the `handskin` app."""
    app.command("view")(view_command)
