"""`handskin view`: a 3D view, the Fig. 1 panel and the 10 Hz sequence of one sample.

The sample comes from a dataset (``DATASET --sample I``: a synthetic dataset is re-simulated from
its stored configuration to place the contactor, a real one is drawn without it) or is simulated
now (``--part P --seed S --sample I``). `register(app)` adds the command (wired in
handskin/cli.py). MuJoCo, pyvista and matplotlib are imported inside the functions that use them,
so that `handskin --help` stays quick.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Annotated

import numpy as np
import typer
from PIL import Image

from sim.skin import DEFAULT_PART
from tactile.config import from_dict
from tactile.dataset.reader import open_dataset
from tactile.errors import ConfigError, DataError, HandskinError, require_positive
from tactile.files import os_error_text, require_output, save_image
from tactile.images.labels import backproject, check_labels

COLORS = ("pressure", "label", "prediction")  # sim.view.render.COLORS, which loads pyvista


def _fail(err: Exception) -> typer.Exit:
    text = err.args[0] if isinstance(err, KeyError) and err.args else err  # no repr quotes
    typer.echo(f"error: {text}", err=True)
    return typer.Exit(2)


def has_display() -> bool:
    """Whether an interactive window can open (X11 or Wayland display set)."""
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def load_predicted(path: Path, tmap, n_taxels: int) -> tuple[np.ndarray, np.ndarray | None]:
    """(per-taxel classes (N,), pixel segmentation (H, W) or None) from a .npy of (N,) taxel
    labels (as ``handskin predict DATASET --sample I --out FILE.npy`` writes) or of an (H, W)
    segmentation (back-projected with `tactile.images.labels.backproject`)."""
    path = Path(path)
    if not path.is_file():
        raise DataError(
            f"--pred {path}: no such file. Fix: write the labels with handskin predict "
            "DATASET --sample I --segmenter CKPT --out FILE.npy"
        )
    try:
        arr = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as err:
        raise DataError(f"--pred {path}: not a .npy array of class ids ({err})") from err
    if arr.shape == tmap.shape:
        return backproject(tmap, arr.astype(np.int64)).astype(np.int64), arr.astype(np.int64)
    if arr.shape == (n_taxels,):
        return check_labels(arr.astype(np.int64), n_taxels), None
    raise DataError(
        f"--pred {path}: shape {arr.shape}; expected ({n_taxels},) taxel labels or "
        f"{tmap.shape} pixel classes"
    )


def from_dataset(path: Path, index: int):
    """(ViewScene or None, tmap, sample dict, sequence images or None) of dataset sample ``index``.

    A synthetic dataset (attrs ``config``) is re-simulated to place the contactor; a real one
    (or another part) gives no 3D scene."""
    from sim.episode.runner import FRAME_DT_S  # start-up: mujoco
    from tactile.figures.panels import common_scale_images  # start-up: matplotlib

    with open_dataset(path) as ds:
        if not 0 <= index < len(ds):
            n = len(ds)
            raise DataError(
                f"--sample {index} out of range; the dataset has {n} samples (0..{n - 1})"
            )
        sample, tmap, config = ds[index], ds.map, ds.attrs.get("config")
        seq = None
        if "seq_raw" in ds.fields:
            raw = sample["seq_raw"][: int(sample["seq_length"])]
            times_s = (np.arange(len(raw)) + 1) * FRAME_DT_S  # frame k at (k + 1) / 10 Hz
            seq = common_scale_images(tmap, ds.pressure_from_raw(raw, times_s))
    if not isinstance(config, dict):
        return None, tmap, sample, seq
    from sim.generate.config import GenerateConfig  # start-up: mujoco
    from sim.view.scenes import simulate_scene  # start-up: mujoco

    try:
        cfg = from_dict(GenerateConfig, config)
    except ConfigError:  # not a synthetic dataset's configuration (e.g. an ingested recording)
        return None, tmap, sample, seq
    return simulate_scene(cfg, index).scene, tmap, sample, seq


def simulated(part: str, seed: int, index: int, sequence: bool):
    """(ViewScene, tmap, sample dict, sequence images or None) of sample ``index`` simulated now."""
    from sim.generate.config import GenerateConfig  # start-up: mujoco
    from sim.view.scenes import sequence_pressure, simulate_scene  # start-up: mujoco
    from tactile.figures.panels import common_scale_images  # start-up: matplotlib

    if index < 0:
        raise ConfigError(f"--sample {index} out of range; allowed >= 0")
    cfg = GenerateConfig(part=part, seed=seed, n=index + 1, keep_sequences=sequence)
    sim = simulate_scene(cfg, index)
    seq = None
    if sequence:
        p = sequence_pressure(sim.ctx, sim.sample["seq_raw"], int(sim.sample["seq_length"]))
        seq = common_scale_images(sim.ctx.tmap, p)
    return sim.scene, sim.ctx.tmap, sim.sample, seq


def write_outputs(scene, tmap, sample, seq, opts: dict) -> list[Path]:
    """Write the requested PNG / GIF files; returns their paths."""
    import tactile.figures.panels as figures  # start-up: matplotlib

    out, view = [], None
    predicted = opts["predicted"]
    if scene is not None and (opts["png"] or opts["panel"] or opts["interactive"]):
        from sim.view.render import render_scene  # start-up: pyvista

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
        out.append(save_image(Image.fromarray(view), opts["png"]))
    if opts["panel"]:
        title = scene.title if scene is not None else ""
        fig = figures.sample_panel(
            view,
            tmap,
            sample["image"],
            sample.get("label_image"),
            np.asarray(sample["pressure_pa"], dtype=float),
            title,
        )
        out.append(figures.save_figure(fig, opts["panel"], dpi=90))
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
            out.append(figures.save_sequence_gif(opts["sequence"], seq, scale=2))
        else:
            out.append(figures.save_figure(figures.sequence_strip(seq), opts["sequence"]))
    return out


def prediction_outputs(
    tmap, sample: dict, predicted, pred_pixels, png: Path, name: str = "predicted"
) -> list[Path]:
    """Figs. 12-13 (image, true, predicted, errors) at ``png`` and Fig. 18's per-part bars
    (true vs predicted taxel labels) beside it (``<stem>_parts.png``)."""
    import tactile.figures.panels as figures  # start-up: matplotlib

    if pred_pixels is None:
        raise DataError(
            "--prediction-png needs --pred as an (H, W) pixel segmentation; for "
            "(N,) taxel labels, handskin predict --png draws these figures"
        )
    pressure = np.asarray(sample["pressure_pa"], dtype=float)
    fig = figures.prediction_figure(
        sample["image"], sample["label_image"], pred_pixels, pred_name=name
    )
    bars = figures.part_bars_figure(
        sample["taxel_label"],
        pressure,
        pred_labels=predicted,
        threshold_pa=0.0,
        title=f"hatched: {name}",
    )
    return [
        figures.save_figure(fig, png, dpi=90),
        figures.save_figure(bars, png.with_name(f"{png.stem}_parts.png"), dpi=90),
    ]


def view_command(
    dataset: Annotated[
        Path | None,
        typer.Argument(
            metavar="DATASET",
            help="Dataset folder (or its dataset.h5); omit to simulate a sample of --part now.",
        ),
    ] = None,
    sample: Annotated[
        int,
        typer.Option(
            help="Sample index (0-based) in DATASET, or of the simulated dataset (with the "
            "default hand fraction, samples 2, 4, 6, ... are hands)."
        ),
    ] = 0,
    part: Annotated[
        str,
        typer.Option(
            help="Part of a simulated sample: forearm_paper, forearm, forearm_8mm, forearm_x2, "
            "forearm_x3, forearm_x4, end_effector or plate."
        ),
    ] = DEFAULT_PART,
    seed: Annotated[int, typer.Option(help="Dataset seed of a simulated sample.")] = 0,
    color: Annotated[
        str,
        typer.Option(
            help="Taxel colours: pressure (kPa colour bar), label (class palette) or prediction "
            "(classes read from --pred)."
        ),
    ] = "pressure",
    pred: Annotated[
        Path | None,
        typer.Option(
            help="Predicted classes for --color prediction: .npy of (N,) taxel class ids or an "
            "(H, W) pixel segmentation (class ids 0..6)."
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
        typer.Option(help="Caption of the predicted labels in the figures, e.g. a model name."),
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
        bool, typer.Option("--interactive", help="Open an interactive 3D window (needs a display).")
    ] = False,
) -> None:
    """Draw one sample: 3D view (part, taxels, contactor in place), Fig. 1 panel, sequence."""
    try:
        if color not in COLORS:
            raise ConfigError(f"--color {color!r} unknown; choose one of {', '.join(COLORS)}")
        if color == "prediction" and pred is None:
            raise ConfigError("--color prediction needs --pred FILE.npy (predicted classes)")
        require_positive("--width", width, "pixels")
        require_positive("--height", height, "pixels")
        if seed < 0:
            raise ConfigError(f"--seed {seed} is out of range; allowed >= 0")
        if interactive and not has_display():
            raise ConfigError("--interactive needs a display (DISPLAY unset); write --png instead")
        if not (png or panel or sequence or interactive or prediction_png):
            png = Path("out/view.png")
        for flag, path, suffixes in (
            ("--png", png, (".png",)),
            ("--panel", panel, (".png",)),
            ("--sequence", sequence, (".gif", ".png")),
            ("--prediction-png", prediction_png, (".png",)),
        ):
            bars = flag == "--prediction-png" and path is not None  # and <stem>_parts.png
            parts = [path.with_name(f"{path.stem}_parts.png")] if bars else []
            require_output(path, flag, reads=[dataset, pred], suffixes=suffixes, derived=parts)
        if dataset is not None:
            scene, tmap, smp, seq = from_dataset(dataset, sample)
        else:
            scene, tmap, smp, seq = simulated(part, seed, sample, sequence is not None)
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
    except OSError as err:  # a full disk while writing the figures
        raise _fail(ValueError(os_error_text(err))) from err
    for path in written:
        typer.echo(f"written: {path}")


def register(app: typer.Typer) -> None:
    """Add `view` to the `handskin` app."""
    app.command("view")(view_command)
