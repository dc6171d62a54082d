"""`handskin quantize`: write a HandsNet checkpoint's int8 network to a file, calibrated once.

``handskin predict --classifier FILE`` and ``handskin evaluate FILE`` then run the saved int8
network without reading training images (`learn.int8_file`). Inputs are checked before any
work; errors print ``error: <what and how to fix>`` and exit with status 2; an existing float
checkpoint is never written over.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from learn.cli import _fail, _opt
from tactile.errors import ConfigError, HandskinError

QuantCkptArg = Annotated[
    Path, typer.Argument(help="HandsNet checkpoint (.pt file written by handskin train).")
]
QuantOutOpt = _opt(
    Path | None,
    "The int8 file to write (.pt; default: <checkpoint "
    "stem>_int8.pt beside the checkpoint). An existing int8 file is replaced; "
    "a float checkpoint is never written over.",
)
QuantCalOpt = _opt(
    Path | None,
    "A dataset or image folder of the same skin whose train split "
    "sets the 8-bit activation ranges (default: the checkpoint's training data).",
)
QuantImagesOpt = _opt(
    int,
    "Calibration images drawn from that train split by the run's seed "
    "(count, at least 16; fewer when the split is smaller).",
)


def quantize_command(
    checkpoint: QuantCkptArg,
    out: QuantOutOpt = None,
    calibration: QuantCalOpt = None,
    images: QuantImagesOpt = 512,
) -> None:
    """HandsNet as an int8 file: calibrated once, run by predict and evaluate as int8."""
    import torch

    from learn.checkpoint import load_checkpoint, model_from_checkpoint, save_checkpoint
    from learn.fastpath import cpu_ms_per_image, prepare_for_inference
    from learn.int8_file import int8_checkpoint, is_int8
    from learn.quantize import (
        MIN_CALIBRATION,
        calibration_images,
        calibration_source,
        int8_supported,
        quantize_int8,
        traceable_body,
    )

    try:
        out = out or checkpoint.with_name(f"{checkpoint.stem}_int8.pt")
        ckpt = load_checkpoint(checkpoint)
        model, run = model_from_checkpoint(ckpt)  # refuses an int8 file
        traceable_body(model)
        if not int8_supported():
            raise ConfigError(
                f"this PyTorch has no oneDNN quantized engine "
                f"({torch.backends.quantized.supported_engines}). Fix: run "
                "HandsNet in float"
            )
        if images < MIN_CALIBRATION:
            raise ConfigError(f"--images {images}: calibrate on at least {MIN_CALIBRATION} images")
        _check_out(out, checkpoint, is_int8)
        where = calibration_source(ckpt, calibration)
        hand = (ckpt.get("data") or {}).get("hand_classes")
        calib = calibration_images(where, run, hand and tuple(hand), images)
        net = quantize_int8(model, calib)
    except (HandskinError, KeyError) as err:
        raise _fail(err) from err
    with torch.no_grad():
        ref, got = model(calib), net(calib)
    agree = float((ref.argmax(1) == got.argmax(1)).float().mean())
    save_checkpoint(int8_checkpoint(ckpt, net, where, len(calib), checkpoint), out)
    size = run.model.input_size
    ms_float = cpu_ms_per_image(prepare_for_inference(model), size, 1, 50)
    ms_int8 = cpu_ms_per_image(net, size, 1, 50)
    typer.echo(
        f"int8 HandsNet written to {out}: activation ranges from {len(calib)} images of "
        f"the train split of {where}; same class as the float network on "
        f"{100 * agree:.2f} % of them; {ms_int8:.2f} ms/image against {ms_float:.2f} "
        f"float (CPU, 1 thread, batch 1)"
    )


def _check_out(out: Path, checkpoint: Path, is_int8) -> None:
    """ConfigError when writing ``out`` would replace the source or a float checkpoint."""
    from learn.checkpoint import load_checkpoint

    if out.resolve() == checkpoint.resolve():
        raise ConfigError(f"--out {out} is the checkpoint itself. Fix: give another file name")
    if out.suffix != ".pt":
        raise ConfigError(f"--out {out}: name the int8 file with a .pt suffix")
    if out.exists():
        try:
            held = load_checkpoint(out)
        except HandskinError:
            held = None
        if held is None or not is_int8(held):
            raise ConfigError(
                f"--out {out} exists and is not an int8 file of handskin "
                "quantize; it is not written over. Fix: give another --out"
            )
