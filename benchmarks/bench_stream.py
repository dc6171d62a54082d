"""Latency of touch recognition frame by frame on one CPU core, before and after the fast frame
path, and frames per second of `handskin stream` end to end on the loopback.

    python benchmarks/bench_stream.py DATA --classifier C.pt --segmenter S.pt [--frames 10000]
        [--network N.pt ...]

DATA's test split gives the frames (raw counts to Pa as the dataset converts them; every one a
touch, cycled to ``--frames``). With one torch and one BLAS thread, each path answers the frames
in blocks, the paths taking turns block by block, so that a shared machine's slow spells weigh
on all of them alike: the old path (`learn.infer.predict.predict_frame`, ``--old-frames`` of
them) and `learn.infer.stream.Recognizer` for the classifier alone, the segmenter alone and
both, with the networks as `load_predictor` gives them (HandsNet's weights in bfloat16 on CPUs
with native bf16, SegNet float32), compiled by TorchInductor, HandsNet in int8 and SegNet's
weights in bfloat16 (compiled), and the compiled networks alone (where the time goes). Printed
with the machine's load average (other processes slow a shared core): median, p99 and max ms
per frame against the targets (full answer 5 ms median and 8 ms p99, the classifier's answer
1.5 ms median); then, on the test split, how many classes and taxel labels of each path differ
from `predict_frame`'s; then `handskin stream --compile` (per-taxel labels included; the networks
of ``--stream``, by default the classifier and the segmenter) fed ``--stream-frames`` frames as
fast as they go through a pipe on standard input and through ZeroMQ on 127.0.0.1, in answered
frames per second, and its marginal wall time per frame over standard input: the whole command
run on N and on 2N frames from a file, (t(2N) - t(N)) / N, so that start-up cancels.
Each ``--network`` is a candidate for the full answer, timed beside them: a class-and-parts
network (``handparts``) alone, or a segmenter paired with the compiled classifier, each on the
frame path and compiled, with its differences from its own `predict_frame`.
Latency does not depend on the weights: networks trained briefly are fine for the timings.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # one core: before numpy starts its pool

import argparse
import itertools
import json
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch

from learn.infer.predict import Predictor, load_map, load_predictor, predict_frame
from learn.infer.stream import Recognizer, bf16_weights, compiled
from learn.numerics import flushing
from learn.train.checkpoint import load_checkpoint
from tactile.dataset import open_dataset

TARGET_MS = {"both": (5.0, 8.0), "classifier": (1.5, None)}  # (median, p99) ms, one core
BLOCK = 500  # frames a path answers before the next takes its turn


def candidate_paths(tmap, networks: list[Path], clf_path: Path) -> dict[str, Callable]:
    """name -> step(p) of each candidate network (``cand <run folder>``): its `predict_frame`
    (the reference of its differences) and its compiled frame path; a segmenter answers with
    the classifier of ``clf_path``, a class-and-parts network alone."""
    clf = load_predictor(clf_path)
    clf_c = compiled(clf)
    out = {}
    for path in networks:
        pred = load_predictor(path)
        name = f"cand {path.parent.name}"
        pair = (pred, None) if pred.task == "both" else (clf, pred)
        out[f"{name} old predict_frame"] = lambda p, c=pair: predict_frame(p, tmap, *c)
        fast = (compiled(pred), None) if pred.task == "both" else (clf_c, compiled(pred))
        out[f"{name} frame path compiled"] = Recognizer(tmap, *fast).step
        out[f"{'network':10s} {name} alone"] = network_alone(
            fast[0] if pred.task == "both" else fast[1]
        )
    return out


def paths(tmap, clf_path: Path, seg_path: Path) -> dict[str, Callable]:
    """name -> step(p): the old path and the recognizers, for each combination of networks."""
    clf, seg = load_predictor(clf_path), load_predictor(seg_path)
    print("compiling (TorchInductor) ...", flush=True)
    clf_c, seg_c = compiled(clf), compiled(seg)
    clf_8, seg_b = load_predictor(clf_path, int8=True), compiled(bf16_weights(seg))
    out = {}
    old = {"classifier": (clf, None), "segmenter": (None, seg), "both": (clf, seg)}
    for combo, (c, s) in old.items():
        out[f"{combo:10s} old predict_frame"] = lambda p, c=c, s=s: predict_frame(p, tmap, c, s)
    nets = {
        "classifier": {"": (clf, None), "compiled": (clf_c, None), "int8": (clf_8, None)},
        "segmenter": {"": (None, seg), "compiled": (None, seg_c), "bf16 compiled": (None, seg_b)},
        "both": {"": (clf, seg), "compiled": (clf_c, seg_c), "compiled, seg bf16": (clf_c, seg_b)},
    }
    for combo, variants in nets.items():
        for name, (c, s) in variants.items():
            out[f"{combo:10s} frame path {name}".rstrip()] = Recognizer(tmap, c, s).step
    for name, pred in (("HandsNet compiled", clf_c), ("SegNet compiled", seg_c)):
        out[f"{'network':10s} {name} alone"] = network_alone(pred)
    return out


def network_alone(pred: Predictor) -> Callable:
    """step(p): ``pred``'s network on a fixed seeded input, ignoring the frame."""
    x = torch.rand(1, 1, *pred.input_size, generator=torch.Generator().manual_seed(0))

    def step(p: np.ndarray) -> torch.Tensor:
        with torch.inference_mode(), flushing():
            return pred.model(x)

    return step


def latencies(steps: dict[str, Callable], frames: np.ndarray, n: int, n_old: int) -> dict:
    """name -> (k, 2) ms per frame, wall clock and this thread's CPU time: ``n`` frames per path
    (``n_old`` for the old path and the networks alone), cycled from ``frames``, the paths
    taking turns block by block after 20 frames of warm-up each."""
    for step in steps.values():
        for p in frames[:20]:
            step(p)
    times = {name: [] for name in steps}
    cycle = itertools.cycle(range(len(frames)))
    for block in range(-(-n // BLOCK)):
        chunk = [frames[next(cycle)] for _ in range(min(BLOCK, n - block * BLOCK))]
        for name, step in steps.items():
            few = "old" in name or name.startswith("network")
            for p in chunk[: -(-n_old * len(chunk) // n)] if few else chunk:
                wall, cpu = time.perf_counter(), time.thread_time()
                step(p)
                times[name].append((time.perf_counter() - wall, time.thread_time() - cpu))
    return {name: 1e3 * np.asarray(t) for name, t in times.items()}


def verdict(name: str, ms: np.ndarray) -> str:
    combo = "both" if name.startswith("cand") else name.split()[0]
    median, p99 = TARGET_MS.get(combo, (None, None))
    out = "" if median is None else f"  median/{median:g} ms = {np.median(ms) / median:.2f}"
    return out + ("" if p99 is None else f", p99/{p99:g} ms = {np.percentile(ms, 99) / p99:.2f}")


def print_latencies(times: dict) -> None:
    print("\nms per frame, wall clock (median, p99, max) and this thread's CPU time (median, p99):")
    heads = "".join(f"{h:>8s}" for h in ("median", "p99", "max", "cpu", "p99"))
    print(f"{'path':44s} {'frames':>6s}{heads}")
    for name, ms in times.items():
        wall, cpu = ms[:, 0], ms[:, 1]
        stats = (np.median(wall), np.percentile(wall, 99), wall.max())
        stats += (np.median(cpu), np.percentile(cpu, 99))
        cells = "".join(f"{v:8.2f}" for v in stats)
        print(f"{name:44s} {len(ms):6d}{cells}{verdict(name, wall)}")
    for combo in ("classifier", "segmenter", "both"):
        old = np.median(times[f"{combo:10s} old predict_frame"][:, 0])
        new = np.median(times[f"{combo:10s} frame path compiled"][:, 0])
        print(f"{combo}: the compiled frame path is {old / new:.1f}x faster than predict_frame")


def differences(steps: dict[str, Callable], frames: np.ndarray, tmap) -> None:
    """Classes and taxel labels of each frame path against `predict_frame`'s on ``frames``."""
    ref = {}
    for name, step in steps.items():
        if "old" in name:
            ref[reference_of(name)] = [step(p) for p in frames]
    labelled = sum(int((r.taxel_labels > 0).sum()) for r in ref["both"])
    print(f"\nagainst predict_frame on the {len(frames)} test frames ({labelled} taxels labelled):")
    for name, step in steps.items():
        if "old" in name or name.startswith("network"):
            continue
        flips, taxels, in_frames = [], 0, 0
        for p, r in zip(frames, ref[reference_of(name)], strict=True):
            a = step(p)
            if a.class_name != r.class_name:
                flips.append(r.probability)
            if a.taxel_labels is not None:
                d = int((a.taxel_labels != r.taxel_labels).sum())
                taxels, in_frames = taxels + d, in_frames + (d > 0)
        near = f" (predict_frame's p <= {max(flips):.3f})" if flips else ""
        print(
            f"  {name:44s} classes differ {len(flips)}{near}, taxel labels {taxels} in "
            f"{in_frames} frames"
        )


def reference_of(name: str) -> str:
    """The `predict_frame` path a frame path is compared with: its combination, or its
    candidate (``cand <run>``)."""
    return " ".join(name.split()[:2]) if name.startswith("cand") else name.split()[0]


def free_address() -> str:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return f"tcp://127.0.0.1:{s.getsockname()[1]}"


def stream_fps(args, lines: list[bytes], zmq: bool) -> str:
    """Answered frames per second of `handskin stream --compile` fed ``lines`` as fast as they
    go, after one frame answered (the command then ready), and its own summary line."""
    cmd = stream_command(args)
    if not zmq:
        return _fps_stdin(cmd, lines)
    import zmq as z  # optional: pyzmq

    inp, out = free_address(), free_address()
    proc = subprocess.Popen([*cmd, "--zmq", inp, "--zmq-out", out], stderr=subprocess.PIPE)
    ctx = z.Context()
    push, pull = ctx.socket(z.PUSH), ctx.socket(z.PULL)
    push.connect(inp)
    pull.connect(out)
    push.send(lines[0])
    pull.recv()
    start = time.perf_counter()
    sender = threading.Thread(target=lambda: [push.send(m) for m in [*lines, b""]])
    sender.start()
    for _ in lines:
        pull.recv()
    fps = len(lines) / (time.perf_counter() - start)
    sender.join()
    summary = proc.communicate(timeout=120)[1].decode().strip().splitlines()[-1]
    ctx.destroy(linger=0)
    return f"{fps:7.0f} frames/s  ({summary})"


def stream_command(args) -> list[str]:
    """`handskin stream --compile` on one thread with the networks of ``--stream``."""
    networks = args.stream or [args.classifier, args.segmenter]
    cmd = [sys.executable, "-c", "from handskin.cli import main; main()", "stream", "--compile"]
    cmd += ["--map", str(args.data), "--threads", "1", "--classifier", str(networks[0])]
    return cmd + (["--segmenter", str(networks[1])] if len(networks) > 1 else [])


def marginal_ms(args, lines: list[bytes]) -> str:
    """Marginal wall time per frame of the whole command over standard input: run on N and on
    2N frames from a file (answers read to the end), (t(2N) - t(N)) / N ms."""
    cmd, walls = stream_command(args), {}
    with tempfile.TemporaryDirectory() as tmp:
        for n in (len(lines), 2 * len(lines)):
            frames = Path(tmp) / f"{n}.csv"
            frames.write_bytes(b"\n".join(itertools.islice(itertools.cycle(lines), n)) + b"\n")
            with frames.open("rb") as inp:
                start = time.perf_counter()
                done = subprocess.run(cmd, stdin=inp, capture_output=True, check=True)
                walls[n] = time.perf_counter() - start
            answered = done.stdout.count(b"\n")
            if answered != n:
                raise SystemExit(f"stream answered {answered} of {n} frames")
    ms = 1000 * (walls[2 * len(lines)] - walls[len(lines)]) / len(lines)
    return (
        f"{ms:6.2f} ms a frame  (whole command: {walls[len(lines)]:.1f} s for {len(lines)}, "
        f"{walls[2 * len(lines)]:.1f} s for {2 * len(lines)})"
    )


def _fps_stdin(cmd: list[str], lines: list[bytes]) -> str:
    proc = subprocess.Popen(
        cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, bufsize=0
    )
    proc.stdin.write(lines[0] + b"\n")
    proc.stdout.readline()
    start = time.perf_counter()
    writer = threading.Thread(target=lambda: [proc.stdin.write(m + b"\n") for m in lines])
    writer.start()
    for _ in lines:
        json.loads(proc.stdout.readline())
    fps = len(lines) / (time.perf_counter() - start)
    writer.join()
    proc.stdin.close()
    summary = proc.stderr.read().decode().strip().splitlines()[-1]
    proc.wait(timeout=120)
    return f"{fps:7.0f} frames/s  ({summary})"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("data", type=Path, help="dataset folder (its test split's frames)")
    parser.add_argument("--classifier", type=Path, required=True, help="HandsNet .pt")
    parser.add_argument("--segmenter", type=Path, required=True, help="SegNet .pt")
    parser.add_argument("--frames", type=int, default=10_000, help="timed frames per path")
    parser.add_argument(
        "--old-frames", type=int, default=2_000, help="of predict_frame, of a network alone"
    )
    parser.add_argument("--stream-frames", type=int, default=2_000, help="per stream test")
    parser.add_argument(
        "--network", type=Path, action="append", default=[], help="a candidate .pt (repeatable)"
    )
    parser.add_argument("--json", type=Path, help="write the latencies (ms) here")
    parser.add_argument(
        "--stream",
        type=lambda text: [Path(p) for p in text.split(",")],
        help="the networks `handskin stream` runs: CLASSIFIER[,SEGMENTER] or a class-and-parts "
        ".pt (default: --classifier,--segmenter)",
    )
    args = parser.parse_args()
    torch.set_num_threads(1)
    tmap, _, to_pa = load_map(args.data)
    with open_dataset(args.data) as ds:
        raw = ds.raw[np.sort(ds.splits["test"])]
    frames = to_pa(raw)
    for which in ("classifier", "segmenter"):
        ckpt = load_checkpoint(getattr(args, which))
        arch = ckpt["config"]["model"]["arch"]
        print(f"{which}: {arch} from {getattr(args, which)}, epoch {ckpt.get('epoch')}")
    print(f"{len(frames)} test frames of {args.data}; torch {torch.__version__}, 1 thread")
    print("load average (1, 5, 15 min) at the start: {:.2f} {:.2f} {:.2f}".format(*os.getloadavg()))
    print("latency does not depend on the weights: briefly trained networks time alike")
    steps = paths(tmap, args.classifier, args.segmenter)
    steps |= candidate_paths(tmap, args.network, args.classifier)
    times = latencies(steps, frames, args.frames, args.old_frames)
    print_latencies(times)
    if args.json:
        summary = {
            name: {
                "median_ms": float(np.median(ms[:, 0])),
                "p99_ms": float(np.percentile(ms[:, 0], 99)),
            }
            for name, ms in times.items()
        }
        args.json.write_text(json.dumps(summary, indent=1))
    print("load average at the end of the timing: {:.2f} {:.2f} {:.2f}".format(*os.getloadavg()))
    differences(steps, frames, tmap)
    lines = [",".join(map(str, r)).encode() for r in raw.astype(np.int64)]
    lines = list(itertools.islice(itertools.cycle(lines), args.stream_frames))
    networks = " + ".join(str(p) for p in args.stream or [args.classifier, args.segmenter])
    print(
        f"\nhandskin stream --compile ({networks}), {len(lines)} frames (CSV lines of raw counts):"
    )
    print(f"  stdin pipe  {stream_fps(args, lines, zmq=False)}")
    print(f"  zmq tcp     {stream_fps(args, lines, zmq=True)}")
    print(f"  marginal    {marginal_ms(args, lines)}")


if __name__ == "__main__":
    main()
