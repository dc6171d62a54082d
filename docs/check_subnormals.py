"""How many subnormal values a checkpoint holds, and what they cost on this CPU.

    python docs/check_subnormals.py CHECKPOINT [--steps 6] [--runs 50]

Counts, per tensor of the checkpoint's model, the float32 values that are subnormal (nonzero and
below 1.2e-38 in magnitude). Then, on one torch thread, times a training step (batch 64 of
seeded random images at the model's input size, SGD with momentum, cross-entropy) and the fast
CPU inference path (``learn.fastpath``, ms per image at batch 1), with subnormals kept (IEEE 754
gradual underflow) and flushed to zero (``learn.numerics.flushing``, handskin's setting). One
thread, so the mode of this thread is the mode of every operation timed.
"""

from __future__ import annotations

import argparse
import contextlib
import time

import torch

from learn.checkpoint import load_checkpoint, model_from_checkpoint
from learn.fastpath import fast_inference
from learn.metrics import time_per_image
from learn.numerics import flushing


def subnormal_counts(state: dict[str, torch.Tensor]) -> dict[str, tuple[int, int]]:
    """Tensor name → (subnormal values, values), for the float32 tensors that hold any. Read
    from the bits (exponent 0, mantissa not), which flush-to-zero modes do not touch."""
    out = {}
    for name, value in state.items():
        if value.dtype == torch.float32:
            bits = value.contiguous().view(torch.int32)
            n = int((((bits & 0x7F800000) == 0) & ((bits & 0x007FFFFF) != 0)).sum())
            if n:
                out[name] = (n, value.numel())
    return out


def seconds_per_step(model: torch.nn.Module, size: tuple[int, int], steps: int) -> float:
    """Mean seconds of a training step (forward, backward, SGD) at batch 64 of ``size`` (h, w)
    px images, after two."""
    gen = torch.Generator().manual_seed(0)
    x = torch.rand(64, model.in_channels, *size, generator=gen)
    shape = (64, *size) if model.task == "segmentation" else (64,)
    y = torch.randint(0, model.num_classes, shape, generator=gen)
    model.train()
    opt = torch.optim.SGD(model.parameters(), lr=1e-6, momentum=0.9)
    for i in range(steps + 2):
        if i == 2:
            start = time.perf_counter()
        opt.zero_grad()
        torch.nn.functional.cross_entropy(model(x), y).backward()
        opt.step()
    return (time.perf_counter() - start) / steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("checkpoint", help="a .pt file from handskin train")
    parser.add_argument("--steps", type=int, default=6, help="training steps timed (count)")
    parser.add_argument("--runs", type=int, default=50, help="timed inference runs (count)")
    args = parser.parse_args()
    torch.set_num_threads(1)
    ckpt = load_checkpoint(args.checkpoint)
    counts = subnormal_counts(ckpt["model"])
    total = sum(v.numel() for v in ckpt["model"].values() if v.is_floating_point())
    print(f"{sum(n for n, _ in counts.values()):,} subnormal of {total:,} float values")
    for name, (n, size) in counts.items():
        print(f"  {name:32s} {n:8,d} of {size:9,d} ({100 * n / size:.1f} %)")
    rows = {}
    for flush in (False, True):
        model, run = model_from_checkpoint(load_checkpoint(args.checkpoint))
        fast, size = fast_inference(model), tuple(run.model.input_size)
        with flushing() if flush else contextlib.nullcontext():
            # time_per_image itself flushes (learn.numerics): its undecorated body here
            ms = 1e3 * time_per_image.__wrapped__(fast, size, n_warmup=20, n_runs=args.runs)
            rows[flush] = (ms, seconds_per_step(model, size, args.steps))
        label = "flushed to zero" if flush else "kept (IEEE)"
        print(
            f"subnormals {label:16s}: fast path {rows[flush][0]:7.2f} ms/image, "
            f"training step (batch 64) {rows[flush][1]:6.3f} s, 1 thread"
        )
    print(
        f"flushing is {rows[False][0] / rows[True][0]:.2f}x faster at inference, "
        f"{rows[False][1] / rows[True][1]:.2f}x in training"
    )


if __name__ == "__main__":
    main()
