"""The typer command of `handskin experiment fidelity` (the work is in `handskin.fidelity`).

No torch import at module level: `handskin --help` works without it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from handskin import fidelity_settings as FS
from learn.experiments.models import DEVICE_HELP
from tactile.errors import HandskinError

_SETTINGS_HELP = (
    "Comma-separated settings to run, cheap to rich; known: "
    + ", ".join(FS.BY_NAME)
    + f". Default: all (quick: {', '.join(FS.QUICK)})."
)


def fidelity_command(
    out: Annotated[
        Path,
        typer.Option(
            "--out",
            help="Report folder (path): report.md, results.json, PNG charts, trained models.",
        ),
    ],
    data: Annotated[
        Path | None,
        typer.Option(
            "--data",
            help="Folder (path) for the generated "
            "datasets, one per setting, reused when complete. Default: OUT/data.",
        ),
    ] = None,
    quick: Annotated[
        bool,
        typer.Option(
            "--quick", help="Small run (< 10 min on 2 cores): 240 samples per setting, 5 settings."
        ),
    ] = False,
    seed: Annotated[
        int,
        typer.Option(
            "--seed", help="Seed (integer >= 0) of every dataset, skin, split and training run."
        ),
    ] = 0,
    settings: Annotated[str | None, typer.Option("--settings", help=_SETTINGS_HELP)] = None,
    n: Annotated[
        int | None,
        typer.Option(
            "--n",
            help="Samples generated per setting (samples; "
            "default 2000, quick 240); 30 % of the richest setting's, by person and "
            "object, form the shared test set.",
        ),
    ] = None,
    epochs: Annotated[
        int | None,
        typer.Option("--epochs", help="Training epochs of each probe (epochs; default 20)."),
    ] = None,
    image_px: Annotated[
        str | None,
        typer.Option(
            "--image-px",
            help="Network input ROWSxCOLUMNS in pixels (default 34x50; the paper's is 68x100).",
        ),
    ] = None,
    workers: Annotated[
        int | None,
        typer.Option("--workers", help="Generator processes (processes; default: all cores)."),
    ] = None,
    part: Annotated[
        str,
        typer.Option(
            "--part",
            help="Skin part (name: forearm, forearm_8mm, "
            "forearm_x2, forearm_x4, end_effector, plate, or a link mesh .stl/.obj in "
            "metres).",
        ),
    ] = "forearm",
    segnet: Annotated[
        bool,
        typer.Option(
            "--segnet",
            help="Also train SegNet on each setting "
            "and report its mean IoU (%) (slow: hours at full size).",
        ),
    ] = False,
    device: Annotated[str, typer.Option("--device", help=DEVICE_HELP)] = "cpu",
    progress: Annotated[
        bool, typer.Option("--progress/--no-progress", help="Progress bars (on/off).")
    ] = True,
) -> None:
    """Fidelity: generation speed (samples per CPU-second) of simulation settings, cheap to rich, vs
    the accuracy (%) of a HandsNet trained on each and tested on the richest setting's data."""
    from handskin.fidelity import parse_image_px, run_fidelity
    from learn.cli import _fail
    from sim.gen_config import check_part

    try:
        check_part(part)
        px = parse_image_px(image_px) if image_px is not None else None
        run_fidelity(
            out,
            data_dir=data,
            settings=settings,
            quick=quick,
            seed=seed,
            n=n,
            epochs=epochs,
            image_px=px,
            workers=workers,
            part=part,
            segnet=segnet,
            device=device,
            progress=progress,
        )
    except (HandskinError, KeyError) as err:
        raise _fail(err) from err
    typer.echo(f"wrote {Path(out) / 'report.md'}")
