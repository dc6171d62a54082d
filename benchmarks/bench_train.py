"""Training speed of the default presets on this CPU: seconds per epoch and per default run.

    python benchmarks/bench_train.py [--steps 30] [--threads 2] [--train-images 2113]

Runs ``--steps`` optimisation steps of each preset's real training step (``learn.train``:
``get_batch`` with the paper's flips, the preset's loss and optimizer) on random images of the
preset's input size, after 3 warm-up steps, and extrapolates to one epoch of ``3 x
--train-images`` views (2,113 = the train part of the paper-sized forearm set after its
validation share; segmenters see only its ~1,010 hand images) and to the preset's epochs.
The learning issue's target: the default HandsNet trains in under 20 minutes on 2 cores.
Printed, never asserted.
"""

from __future__ import annotations

import argparse
import time

import torch

from learn.experiments.models import preset_run
from learn.folder import TensorData
from learn.train import N_VIEWS, build, get_batch, make_loss

HAND_SHARE = 1710 / 3530  # segmenters train on hand samples only (paper's class balance)


def step_seconds(arch: str, steps: int, threads: int) -> tuple[float, object]:
    """Median seconds of one optimisation step of ``arch``'s preset; the run config."""
    torch.set_num_threads(threads)
    run = preset_run(arch)
    h, w = run.model.input_size
    n, bs = 256, run.train.batch_size
    gen = torch.Generator().manual_seed(0)
    x = torch.rand(n, 1, h, w, generator=gen) * (torch.rand(n, 1, h, w, generator=gen) < 0.1)
    y = (torch.randint(0, run.model.num_classes, (n, h, w), generator=gen)
         if run.task == "segment" else torch.randint(0, 2, (n,), generator=gen))  # fmt: skip
    data = TensorData(x, y)
    model, optimizer, _ = build(run)
    loss_fn = make_loss(run, data)
    model.train()
    times = []
    for i in range(steps + 3):
        items = torch.randint(0, n * N_VIEWS, (bs,), generator=gen)
        tic = time.perf_counter()
        xb, yb = get_batch(data, items, N_VIEWS)
        if run.task == "classify":
            xb = xb.contiguous(memory_format=torch.channels_last)
        loss = loss_fn(model(xb), yb)
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
        if i >= 3:
            times.append(time.perf_counter() - tic)
    return float(torch.tensor(times).median()), run


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=30, help="timed steps per model (count)")
    parser.add_argument("--threads", type=int, default=2, help="torch CPU threads (count)")
    parser.add_argument("--train-images", type=int, default=2113, help="train samples (count)")
    parser.add_argument("--archs", nargs="+", default=["handsnet", "segnet", "fcn16s"])
    args = parser.parse_args()
    print(f"threads {args.threads}, {args.train_images} train samples x {N_VIEWS} views")
    for arch in args.archs:
        sec, run = step_seconds(arch, args.steps, args.threads)
        share = 1.0 if run.task == "classify" else HAND_SHARE
        steps_per_epoch = args.train_images * share * N_VIEWS / run.train.batch_size
        epoch_s = sec * steps_per_epoch
        total_min = epoch_s * run.train.epochs / 60
        note = " (target < 20 min)" if arch == "handsnet" else ""
        print(f"{arch:9s} {run.train.batch_size / sec:7.1f} img/s  {epoch_s:6.1f} s/epoch  "
              f"{run.train.epochs} epochs = {total_min:5.1f} min{note}")  # fmt: skip


if __name__ == "__main__":
    main()
