"""Training speed of the default presets on this CPU: seconds per epoch and per default run.

    python benchmarks/bench_train.py [--images 320] [--threads 2] [--train-images 2113]
        [--precision fp32 bf16] [--size 68 100]

Times one epoch of each preset's real training loop (``learn.train.loop.train_epoch``: the
preset's views — the paper's flips —, loss and optimizer) over ``--images`` random images of
the preset's input size, after a short warm-up epoch, and extrapolates to one epoch of
``--train-images`` samples in each view (``learn.train.loop.views_of``: 3 by default; 2,113 = the
train part of the paper-sized forearm set after its validation share; segmenters see only its
~1,010 hand images) and to the preset's epochs. With two ``--precision`` values
(``RunConfig.precision``: bf16 autocasts the forward pass) each arch is timed in both and the
ratio printed; bf16 is skipped, with the reason, on a CPU without native bfloat16.
The learning issue's target: the default HandsNet trains in under 20 minutes on 2 cores.
Printed, never asserted.
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import torch

from learn.config import PRECISIONS, preset_run
from learn.data.load import TensorData
from learn.train.device import bf16_supported
from learn.train.loop import build, make_loss, train_epoch, views_of

HAND_SHARE = 1710 / 3530  # segmenters train on hand samples only (paper's class balance)


def images_per_second(
    arch: str, n: int, threads: int, precision: str = "fp32", size: tuple[int, int] | None = None
) -> tuple[float, object]:
    """Training images per second of ``arch``'s preset (input ``size`` (h, w) px if given): one
    ``learn.train.loop.train_epoch`` (the real step: views, loss, optimizer) over ``n`` random
    sparse images in each of the preset's views, after a warm-up epoch over 64 of them; also
    returns the run config."""
    torch.set_num_threads(threads)
    run = dataclasses.replace(preset_run(arch), precision=precision)
    if size is not None:
        run = dataclasses.replace(run, model=dataclasses.replace(run.model, input_size=size))
    h, w = run.model.input_size
    gen = torch.Generator().manual_seed(0)
    x = torch.rand(n, 1, h, w, generator=gen) * (torch.rand(n, 1, h, w, generator=gen) < 0.1)
    y = (
        torch.randint(0, run.model.num_classes, (n, h, w), generator=gen)
        if run.task == "segment"
        else torch.randint(0, 2, (n,), generator=gen)
    )
    data = TensorData(x, y)
    model, optimizer, _ = build(run)
    loss_fn = make_loss(run, data)
    train_epoch(model, TensorData(x[:64], y[:64]), loss_fn, optimizer, run, 0, False)
    tic = time.perf_counter()
    train_epoch(model, data, loss_fn, optimizer, run, 1, False)
    return n * len(views_of(run)) / (time.perf_counter() - tic), run


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--images", type=int, default=320, help="timed samples, each in every view (count)"
    )
    parser.add_argument("--threads", type=int, default=2, help="torch CPU threads (count)")
    parser.add_argument("--train-images", type=int, default=2113, help="train samples (count)")
    parser.add_argument("--archs", nargs="+", default=["handsnet", "segnet", "fcn16s"])
    parser.add_argument(
        "--precision",
        nargs="+",
        default=["fp32"],
        choices=PRECISIONS,
        help="number formats of the forward pass to time (RunConfig.precision)",
    )
    parser.add_argument(
        "--size",
        nargs=2,
        type=int,
        default=None,
        metavar=("H", "W"),
        help="input size (px) instead of the presets' 68 x 100",
    )
    args = parser.parse_args()
    precisions = [p for p in args.precision if p == "fp32" or bf16_supported()]
    if len(precisions) < len(args.precision):
        print("bf16 skipped: this CPU has no native bfloat16 (AVX512-BF16 / AMX)")
    print(f"threads {args.threads}, {args.train_images} train samples, each in every view")
    for arch in args.archs:
        rates = {}
        for precision in precisions:
            rate, run = images_per_second(
                arch, args.images, args.threads, precision, tuple(args.size) if args.size else None
            )
            rates[precision] = rate
            share = 1.0 if run.task == "classify" else HAND_SHARE
            epoch_s = args.train_images * share * len(views_of(run)) / rate
            total_min = epoch_s * run.train.epochs / 60
            note = " (target < 20 min)" if arch == "handsnet" else ""
            h, w = run.model.input_size
            print(
                f"{arch:9s} {h}x{w} {precision} {rate:7.1f} img/s  {epoch_s:6.1f} s/epoch  "
                f"{run.train.epochs} epochs = {total_min:5.1f} min{note}"
            )
        if len(rates) == 2:
            print(f"{arch:9s} bf16 / fp32 speed: {rates['bf16'] / rates['fp32']:.2f} x")


if __name__ == "__main__":
    main()
