"""CPU (and GPU when present) time per image of every network at batch size 1, after warm-up.

    python benchmarks/bench_models.py [--runs 50] [--widths 1.0 0.5] [--size 68 100]

Prints, for each registered model at its default width, its `handskin train` preset's width
(`learn.config`: 0.25 for VGG16, SegNet and FCN-16s) and any extra ``--widths``, the
parameter count and the median ms / image with 1 and 2 CPU threads, as built (eval mode) and
after ``prepare_for_inference`` (batch norm folded, channels-last), against the targets
HandsNet ≤ 3 ms and SegNet ≤ 60 ms per image on one CPU core. Then the ensemble of the CPU
segmenter presets (SegNet and FCN-16s at width 0.25, the mean of their softmax: ``handskin
evaluate --ensemble``), with and without test-time flips, against the same SegNet target. Then
HandsNet as an int8 network (``learn.infer.quantize``, oneDNN; activation ranges from 64 seeded
sparse random images, which set the scales but not the kernels' speed) against the prepared
float one. Each figure is the least, over ``--rounds`` rounds in which a row's paths take
turns, of the median of ``--runs`` runs, so a shared machine's slow spells weigh on every path
of a row alike. Figures are printed, never asserted: they depend on the machine and its load.
"""

from __future__ import annotations

import argparse
import inspect

import torch
from torch import nn

from learn import config as C
from learn.infer.ensemble import FlipTTA, MeanSoftmax
from learn.infer.fastpath import interleaved_cpu_ms, time_per_image
from learn.infer.quantize import int8_supported, quantize_int8
from learn.inputs import PAPER_VIEWS
from learn.models import MODELS, count_parameters, create_model, prepare_for_inference

TARGET_MS_ONE_CORE = {"handsnet": 3.0, "segnet": 60.0}  # ms per image, one CPU core


PRESET_WIDTH = {
    run.model.arch: run.model.width for run in (C.HANDSNET, C.VGG16_FINETUNE, C.SEGNET, C.FCN16S)
}


def default_width(arch: str) -> float | None:
    """The constructor's default ``width`` (None for fixed-width networks)."""
    param = inspect.signature(MODELS[arch]).parameters.get("width")
    return None if param is None else param.default


def timed(
    nets: list[nn.Module], size: tuple[int, int], runs: int, rounds: int, threads: int
) -> list[float]:
    """ms / image of each network at ``threads`` threads (`interleaved_cpu_ms`: the least over
    ``rounds`` rounds of the median of ``runs`` runs, the networks taking turns in each)."""
    return interleaved_cpu_ms(nets, size, threads, runs, rounds)


def verdict(arch: str, ms_one_core: float) -> str:
    target = TARGET_MS_ONE_CORE.get(arch)
    if target is None:
        return ""
    return f"  target ≤ {target:g}: {'ok' if ms_one_core <= target else 'MISSED'}"


def bench_one(arch: str, width: float | None, size: tuple[int, int], runs: int, rounds: int) -> str:
    """One printed row: arch, width, parameters, ms / image at 1 and 2 threads as built and
    prepared (and on the GPU)."""
    kw = {"input_size": size} if arch == "handsnet" else {"width": width}
    model = create_model(arch, **kw).eval()
    nets = [model, prepare_for_inference(model)]
    by_threads = {t: timed(nets, size, runs, rounds, t) for t in (1, 2)}
    cells = [by_threads[t][i] for i in range(2) for t in (1, 2)]
    gpu = ""
    if torch.cuda.is_available():
        gpu = f"  gpu {1e3 * time_per_image(model, size, 'cuda', n_runs=runs):7.2f}"
    w = "fixed" if width is None else f"{width:g}"
    times = "".join(f"{c:9.2f}" for c in cells)
    return f"{arch:9s} {w:>6s} {count_parameters(model):>12,d}{times}{gpu}{verdict(arch, cells[2])}"


def bench_ensemble(size: tuple[int, int], runs: int, rounds: int, width: float = 0.25) -> list[str]:
    """Printed rows: SegNet + FCN-16s (mean softmax) at ``width``, prepared, 1 and 2 threads,
    without and with test-time flips, against the SegNet target on one core."""
    members = [
        prepare_for_inference(create_model(a, width=width).eval()) for a in ("segnet", "fcn16s")
    ]
    rows = []
    for name, net in (
        ("mean", MeanSoftmax(members)),
        ("mean+flips", MeanSoftmax([FlipTTA(m, PAPER_VIEWS) for m in members])),
    ):
        (one,), (two,) = (timed([net], size, runs, rounds, t) for t in (1, 2))
        rows.append(
            f"segnet+fcn16s {name:10s} w{width:g}: 1 thread {one:7.2f}, 2 threads {two:7.2f}"
            + verdict("segnet", one)
        )
    return rows


def bench_int8(size: tuple[int, int], runs: int, rounds: int) -> str:
    """Printed row: HandsNet prepared (float) and int8, 1 and 2 threads, the int8 speed-up and
    the HandsNet target on one core."""
    if not int8_supported():
        return "handsnet int8: skipped, this PyTorch has no oneDNN quantized engine"
    model = create_model("handsnet", input_size=size).eval()
    calib = torch.rand(64, 1, *size, generator=torch.Generator().manual_seed(0)) ** 4
    nets = [prepare_for_inference(model), quantize_int8(model, calib)]
    (f1, q1), (f2, q2) = (timed(nets, size, runs, rounds, t) for t in (1, 2))
    target = TARGET_MS_ONE_CORE["handsnet"]
    return (
        f"handsnet float prep 1 {f1:7.2f}, prep 2 {f2:7.2f} | int8 1 {q1:7.2f}, int8 2 "
        f"{q2:7.2f} | int8 {f1 / q1:.2f}x faster on 1 core, target ≤ {target:g}: "
        f"{'ok' if q1 <= target else 'MISSED'}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=50, help="timed runs after 10 warm-up runs")
    parser.add_argument("--widths", type=float, nargs="*", default=[], help="extra widths")
    parser.add_argument("--size", type=int, nargs=2, default=(68, 100), help="H W in pixels")
    parser.add_argument(
        "--rounds",
        type=int,
        default=3,
        help="rounds of timing, paths taking turns; the least median is kept",
    )
    args = parser.parse_args()
    size = tuple(args.size)
    print(
        f"input 1 × 1 × {size[0]} × {size[1]}, batch 1, least over {args.rounds} rounds of "
        f"the median of {args.runs} runs, torch {torch.__version__}"
    )
    print("ms / image: as built, prepared (each 1 thread, 2 threads)")
    print(
        f"{'model':9s} {'width':>6s} {'parameters':>12s}"
        + "".join(f"{h:>9s}" for h in ("built 1", "built 2", "prep 1", "prep 2"))
    )
    for arch in MODELS:
        widths = [default_width(arch)]
        if widths[0] is not None:
            extra = [PRESET_WIDTH.get(arch), *args.widths]
            widths += sorted({w for w in extra if w is not None} - set(widths), reverse=True)
        for width in widths:
            print(bench_one(arch, width, size, args.runs, args.rounds), flush=True)
    print("ensemble of the CPU segmenter presets, ms / image:")
    for row in bench_ensemble(size, args.runs, args.rounds):
        print(row, flush=True)
    print("HandsNet as an int8 network (oneDNN), ms / image:")
    print(bench_int8(size, args.runs, args.rounds), flush=True)


if __name__ == "__main__":
    main()
