"""`handskin export`, `ingest`, `sheet`: PNG folders and contact sheets of a dataset, datasets
from recordings."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from tactile.dataset.boxes import ingest_boxes, parse_frame
from tactile.dataset.export import export_png
from tactile.dataset.ingest import ingest_recording
from tactile.dataset.reader import open_dataset
from tactile.dataset.verify import verify_dataset
from tactile.errors import DataError, HandskinError, require_positive
from tactile.files import require_output

CLASSES = ("hand", "non_hand")


def _fail(err: Exception) -> None:
    typer.echo(f"error: {err}", err=True)
    raise typer.Exit(2) from err


def export_command(
    dataset_dir: Annotated[
        Path,
        typer.Argument(
            metavar="DATASET", help="Dataset folder (holding dataset.h5) or the dataset.h5 file."
        ),
    ],
    out: Annotated[
        Path,
        typer.Option(
            help="Output folder of PNG images: 8-bit grey tactile images (1 pixel = the map's "
            "step_mm) in hand/ and non_hand/, RGB label images in labels/."
        ),
    ],
    progress: Annotated[
        bool, typer.Option("--progress/--no-progress", help="Show a progress bar.")
    ] = True,
) -> None:
    """Export a dataset's tactile images and label images as PNG files.

    OUT must be new, empty, or an export of the same dataset (then resumed, files kept)."""
    try:
        require_output(out, "--out", reads=[dataset_dir], folder=True)
        written = export_png(dataset_dir, out, progress=progress)
    except HandskinError as err:
        _fail(err)
    for folder, n in sorted(written.items()):
        typer.echo(f"{folder:<11}{n} PNG files")
    typer.echo(f"written to {out}")


def ingest_command(
    layout: Annotated[
        Path,
        typer.Argument(
            metavar="LAYOUT", help="Taxel layout file: iCub .txt, .csv (positions in m) or .npz."
        ),
    ],
    frames: Annotated[
        Path,
        typer.Argument(
            metavar="FRAMES",
            help="Frames, .csv or .npy, one frame per row, raw 16-bit counts: C = n_channels "
            "columns (raw channel frames) or N = n_taxels columns (taxel frames).",
        ),
    ],
    out: Annotated[Path, typer.Option(help="Output dataset folder (new or empty; a folder path).")],
    labels: Annotated[
        Path | None,
        typer.Option(
            help="Per-frame class labels (.csv/.npy, one per frame, unitless): "
            "1 or hand, 0 or non_hand."
        ),
    ] = None,
    part_labels: Annotated[
        Path | None,
        typer.Option(
            help="Per-taxel part labels (.csv/.npy, T rows x N columns, unitless "
            "class ids 0..6 of tactile.CLASS_NAMES)."
        ),
    ] = None,
    baseline: Annotated[
        Path | None,
        typer.Option(
            help="Untouched frames (.csv/.npy, raw counts, same columns as FRAMES); "
            "their mean per taxel is subtracted. Default: 0 counts."
        ),
    ] = None,
    step_mm: Annotated[float, typer.Option(help="Grid step of the tactile image, mm/pixel.")] = 1.0,
    counts_per_pa: Annotated[
        float,
        typer.Option(help="Skin gain, counts/Pa; 1.0 leaves pressures in counts (uncalibrated)."),
    ] = 1.0,
) -> None:
    """Turn a real skin recording (layout + frames) into a handskin dataset folder."""
    try:
        require_positive("--step-mm", step_mm, "mm/pixel")
        require_positive("--counts-per-pa", counts_per_pa, "counts/Pa")
        inputs = [layout, frames, labels, part_labels, baseline]
        require_output(out, "--out", reads=inputs, folder=True, makes="dataset")
        path = ingest_recording(
            layout,
            frames,
            out,
            labels_path=labels,
            part_labels_path=part_labels,
            baseline_path=baseline,
            step_mm=step_mm,
            counts_per_pa=counts_per_pa,
        )
    except HandskinError as err:
        _fail(err)
    typer.echo(f"dataset written to {path}")


def select_samples(
    ds, cls: str | None = None, action: str | None = None, subject: int | None = None, n: int = 24
) -> np.ndarray:
    """(K,) int64 indices, K <= n, spread evenly over the samples matching every filter.

    ds : an open dataset. cls : "hand" or "non_hand". action : a name of attr ``actions``.
    subject : a subject id (int). DataError names an unknown value or an empty selection.
    """
    keep = np.ones(len(ds), dtype=bool)
    given = {"--class": (cls, "is_hand"), "--action": (action, "action")}
    for flag, (value, name) in (given | {"--subject": (subject, "subject_id")}).items():
        if value is not None and name not in ds.fields:
            raise DataError(
                f"{flag}: {ds.path} has no {name!r} field (its fields: {', '.join(ds.fields)}). "
                f"Fix: leave {flag} out"
            )
    if cls is not None:
        if cls not in CLASSES:
            raise DataError(f"--class {cls!r}: choose one of {', '.join(CLASSES)}")
        keep &= (ds["is_hand"][()] == 1) == (cls == "hand")
    if action is not None:
        names = list(ds.attrs.get("actions", []))
        if action not in names:
            raise DataError(f"--action {action!r} unknown; actions: {', '.join(names) or 'none'}")
        keep &= ds["action"][()] == names.index(action)
    if subject is not None:
        keep &= ds["subject_id"][()] == subject
    found = np.flatnonzero(keep)
    if not len(found):
        raise DataError("no sample matches --class/--action/--subject; relax the filters")
    pick = np.unique(np.linspace(0, len(found) - 1, min(n, len(found))).round().astype(int))
    return found[pick]


def _caption(ds, i: int) -> str:
    desc = json.loads(ds.sample_field("contactor", i)) if "contactor" in ds.fields else {}
    if isinstance(desc, list):  # several contacts: each one's name (a hand's with its person)
        return f"#{i} " + " + ".join(_contact_name(d) for d in desc)
    if "is_hand" in ds.fields and ds["is_hand"][i]:
        names = list(ds.attrs.get("actions", []))
        a = int(ds["action"][i]) if "action" in ds.fields else -1
        who = f"s{int(ds['subject_id'][i])}" if "subject_id" in ds.fields else "hand"
        return f"#{i} {who} {names[a] if 0 <= a < len(names) else ''}".strip()
    return f"#{i} {desc.get('name', 'non-hand')} {desc.get('press', '')}".strip()


def _contact_name(desc: dict) -> str:
    """ "s7 left_hand" for a hand of subject s0007, the type's name for an object or body part."""
    person = str(desc.get("subject", ""))
    number = f"s{int(person[1:])} " if person[1:].isdigit() else ""
    return f"{number}{desc.get('name', '?')}"


def write_sheet(dataset_dir: Path, png: Path, n: int = 24, **filters) -> Path:
    """Contact sheet (PNG) of up to ``n`` samples of a dataset, label colours over the images."""
    from tactile.figures.sheet import save_contact_sheet  # start-up: matplotlib

    with open_dataset(dataset_dir) as ds:
        idx = select_samples(ds, n=n, **filters)
        images = np.stack([ds["image"][i] for i in idx])
        stack = lambda name: (  # noqa: E731
            np.stack([ds[name][i] for i in idx]) if name in ds.fields else None
        )
        labels, instances = stack("label_image"), stack("instance_image")
        title = f"{ds.attrs.get('part', '')}: {len(idx)} of {len(ds)} samples"
        return save_contact_sheet(
            png,
            images,
            labels=labels,
            instances=instances,
            n_cols=6,
            title=title,
            titles=[_caption(ds, int(i)) for i in idx],
        )


def sheet_command(
    dataset_dir: Annotated[
        Path,
        typer.Argument(
            metavar="DATASET", help="Dataset folder (holding dataset.h5) or the dataset.h5 file."
        ),
    ],
    png: Annotated[Path, typer.Option(help="Output PNG file (100 dpi; one tile per sample).")],
    cls: Annotated[
        str | None, typer.Option("--class", help="Only hand or non_hand samples (class name).")
    ] = None,
    action: Annotated[
        str | None,
        typer.Option(help="Only this action (name, e.g. grasp, push_left; see attr `actions`)."),
    ] = None,
    subject: Annotated[
        int | None, typer.Option(help="Only this subject (integer id, e.g. 7 for s0007).")
    ] = None,
    n: Annotated[
        int,
        typer.Option(
            "--n", help="Number of tiles (count), spread evenly over the matching samples."
        ),
    ] = 24,
) -> None:
    """Contact sheet of a dataset: tactile images with label colours and the class legend."""
    try:
        if n < 1:
            raise DataError(f"--n {n} is out of range; allowed >= 1")
        require_output(png, "--png", reads=[dataset_dir], suffixes=(".png",))
        path = write_sheet(dataset_dir, png, n, cls=cls, action=action, subject=subject)
    except HandskinError as err:
        _fail(err)
    typer.echo(f"contact sheet: {path}")


def verify_command(
    dataset_dir: Annotated[
        Path,
        typer.Argument(
            metavar="DATASET", help="Dataset folder (holding dataset.h5) or the dataset.h5 file."
        ),
    ],
    progress: Annotated[
        bool, typer.Option("--progress/--no-progress", help="Show a progress bar.")
    ] = True,
) -> None:
    """Check a dataset end to end: content hash, checksums, every sample, map, splits, chunks.

    Exit status 0 when no fault is found, 1 when one is (each named with its fix), 2 when
    DATASET is not a dataset.
    """
    try:
        report = verify_dataset(dataset_dir, progress=progress)
    except HandskinError as err:
        _fail(err)
    for line in report.ok:
        typer.echo(f"ok     {line}")
    for line in report.notes:
        typer.echo(f"note   {line}")
    for line in report.faults:
        typer.echo(f"FAULT  {line}")
    where = report.path if report.path.exists() else report.path.parent
    if report.faults:
        typer.echo(f"error: {len(report.faults)} fault(s) in {where}", err=True)
        raise typer.Exit(1)
    typer.echo(f"{where}: no fault found")


def ingest_boxes_command(
    folder: Annotated[
        Path,
        typer.Argument(
            metavar="FOLDER",
            help="Box-labelled prints: images/ and labels/ (YOLO .txt: class cx cy w h, "
            "normalised), e.g. ../shared/data/real_hands/fold1.",
        ),
    ],
    out: Annotated[Path, typer.Option(help="Output folder (new or empty).")],
    classes: Annotated[
        str | None,
        typer.Option(
            help="The label files' class names in order, comma-separated (default: the "
            "folder's data.yaml), e.g. palm,thumb,index,middle,ring,pinkie."
        ),
    ] = None,
    frame: Annotated[
        str | None,
        typer.Option(
            help="The images' native frame, ROWSxCOLUMNS px at 1 mm, that each stretched image "
            "is resized back to, e.g. 247x362 (default: as stored)."
        ),
    ] = None,
) -> None:
    """Copy real box-labelled prints into a folder that describes itself: images in their native
    frame, the label files, and a data.yaml with the part names, the frame and labels_from:
    boxes. handskin train, evaluate and stats read it without further flags."""
    try:
        require_output(out, "--out", reads=[folder], folder=True)
        names = [c.strip() for c in classes.split(",")] if classes else None
        path = ingest_boxes(folder, out, names, parse_frame(frame))
    except HandskinError as err:
        _fail(err)
    typer.echo(f"box folder written to {path} ({len(list((path / 'images').iterdir()))} prints)")


def register(app: typer.Typer) -> None:
    """Add `export`, `ingest`, `ingest-boxes`, `sheet` and `verify` to the `handskin` app."""
    app.command("export")(export_command)
    app.command("ingest")(ingest_command)
    app.command("ingest-boxes")(ingest_boxes_command)
    app.command("sheet")(sheet_command)
    app.command("verify")(verify_command)
