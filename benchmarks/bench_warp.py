"""The warp backend's speed on warp's CPU device beside the C backend's, and a GPU projection.

Figures (default forearm, one process, CPU seconds of this process and wall time):
- *C backend*: samples 0..n-1 through `sim.generate.sampler.sample_at` (what a C worker runs).
- *warp, hand family*: the first W hand samples (attempt 0) stepped as one batch of W worlds, for
  W in 8, 32, 128, prepared, stepped, read and made into samples by `sim.warp.backend`; the time
  split between preparing (C scene, device model), stepping (``mjw.step``/``forward``) and the
  host's per-frame readout and sample making. Every hand is one structure family, so this is the
  backend's best case.
- *warp, all samples*: `handskin generate --backend warp` on samples 0..n-1 (hands and the ~25
  families of objects and body parts, whose batches are small), ``--worlds 32``.
- *GPU projection* (not a measurement): MJWarp's published humanoid throughput on a named GPU,
  scaled by the ratio of this scene's per-world step cost to the humanoid's, both measured here
  on the CPU device as the slope of step time over world count (launch overhead removed); plus
  the per-batch-step launch overhead (the CPU device's intercept, an upper bound) for batches of
  `GPU_WORLDS` worlds, for the hand family and for the default mix of structure families; and
  the host work per sample (C scene, device model, readout, images) measured here, which bounds
  each host process. Assumes the GPU keeps the CPU device's cost ratio between the two scenes.

Kernels compile on first use (minutes, cached in ~/.cache/warp); a warm-up batch runs first.
Run: ``OMP_NUM_THREADS=1 PYTHONPATH=. python benchmarks/bench_warp.py [n_all]`` (3-5 min here).
"""

from __future__ import annotations

import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import mujoco
import numpy as np

from sim.generate import sampler
from sim.generate.config import GenerateConfig
from sim.warp.options import WarpOptions, check_warp

check_warp(WarpOptions())  # quiet warp before it starts
import mujoco_warp as mjw  # noqa: E402
import warp as wp  # noqa: E402

from sim.warp import backend as warp_backend  # noqa: E402
from sim.warp.jobs import JobMaker  # noqa: E402
from sim.warp.run import generate as warp_generate  # noqa: E402

# MJWarp's published throughput (steps/s, all worlds) of its humanoid (27 DoF, 20 geoms, Newton,
# pyramidal cones), 8192 worlds on an NVIDIA RTX PRO 6000 Blackwell: pull request
# google-deepmind/mujoco_warp#1060 (2026-01-19, "Perf numbers on an RTX 6000 Pro Blackwell").
PUBLISHED_STEPS_PER_S = 3_973_340
PUBLISHED = "humanoid, 8192 worlds, RTX PRO 6000 Blackwell (mujoco_warp PR #1060)"
GPU_WORLDS = 4096  # worlds per batch assumed on the GPU
TIMES: Counter = Counter()


def timed(name: str, owner, attr: str) -> None:
    """Wrap owner.attr so that its CPU time adds to TIMES[name] and its calls to TIMES[#name]."""
    fn = getattr(owner, attr)

    def wrapper(*args, **kw):
        t0 = time.process_time()
        try:
            return fn(*args, **kw)
        finally:
            TIMES[name] += time.process_time() - t0
            TIMES["#" + name] += 1

    setattr(owner, attr, wrapper)


def c_backend(n: int) -> float:
    state = sampler.build_state(GenerateConfig(n=n))
    t0 = time.process_time()
    for i in range(n):
        sampler.sample_at(i, state)
    rate = n / (time.process_time() - t0)
    print(f"C backend: {n} samples, {rate:.1f} labelled samples per CPU-second")
    return rate


def hand_family(state, maker: JobMaker, worlds: int) -> dict:
    """One batch of ``worlds`` hand episodes: timings and world-steps per sample."""
    hands = [i for i in range(4 * worlds) if sampler.is_hand_index(i, state.cfg.hand_fraction)]
    pending = [warp_backend.Pending(i) for i in hands[:worlds]]
    TIMES.clear()
    t0, w0 = time.process_time(), time.perf_counter()
    trials = [warp_backend.make_trial(state, maker, p) for p in pending]
    t_prep = time.process_time() - t0
    opts = WarpOptions(worlds=worlds)
    outcomes = warp_backend.run_trials(trials, state.ctx, opts)
    for trial, outcome in zip(trials, outcomes, strict=True):
        warp_backend.settle(state, trial, outcome)
    t_run = time.process_time() - t0 - t_prep
    kept = [p.kept for p in pending if p.kept is not None]
    t1 = time.process_time()
    for a in kept:
        warp_backend.finish_sample(state, a)
    cpu, wall = time.process_time() - t0, time.perf_counter() - w0
    steps = TIMES["#step"] + TIMES["#forward"]
    return {
        "worlds": worlds,
        "rate": len(kept) / cpu,
        "wall_rate": len(kept) / wall,
        "prepare": t_prep,
        "step": TIMES["step"] + TIMES["forward"],
        "read": t_run - TIMES["step"] - TIMES["forward"],
        "samples": time.process_time() - t1,
        "cpu": cpu,
        "step_calls": steps,
        "world_steps_per_sample": steps * worlds / max(len(kept), 1),
        "kept": len(kept),
    }


def slope(step_s: dict[int, float]) -> tuple[float, float]:
    """(per-world, per-call) CPU seconds of a step from {worlds: seconds per step}: a line fit."""
    w = np.array(sorted(step_s), float)
    b, a = np.polyfit(w, [step_s[int(x)] for x in w], 1)
    return float(b), float(a)


def humanoid_step_s(worlds: int, nstep: int = 20) -> float:
    """CPU seconds per ``mjw.step`` of MJWarp's test humanoid with ``worlds`` worlds."""
    path = Path(mjw.__file__).parent / "test_data" / "humanoid" / "humanoid.xml"
    mjm = mujoco.MjModel.from_xml_path(str(path))
    with wp.ScopedDevice("cpu"):
        m, d = mjw.put_model(mjm), mjw.make_data(mjm, nworld=worlds, nconmax=24, njmax=64)
        for _ in range(5):
            mjw.step(m, d)
        t0 = time.process_time()
        for _ in range(nstep):
            mjw.step(m, d)
    return (time.process_time() - t0) / nstep


def all_samples(n: int, worlds: int = 32) -> float:
    cfg = GenerateConfig(n=n, backend="warp")
    with tempfile.TemporaryDirectory() as tmp:
        run = warp_generate(
            cfg, Path(tmp) / "ds", workers=1, progress=False, warp=WarpOptions(worlds)
        )
    print(
        f"warp, all samples: {n} samples, --worlds {worlds}: {run.samples_per_s:.2f} samples/s "
        f"wall ({run.wall_s:.0f} s, rejects {run.rejects})"
    )
    return run.samples_per_s


def family_shares(state, maker: JobMaker, n: int) -> list[float]:
    """Shares of samples 0..n-1 (attempt 0) in each structure family, largest first."""
    count: Counter = Counter()
    for i in range(n):
        count[warp_backend.make_trial(state, maker, warp_backend.Pending(i)).key_model.digest] += 1
    return sorted((c / n for c in count.values()), reverse=True)


def projection(rows: list[dict], ours: float, humanoid: float, shares: list[float]) -> None:
    """Print the GPU projection (see the module docstring); per-world and per-call costs in s."""
    ratio = ours / humanoid
    big = rows[-1]
    world_step_s = ratio / PUBLISHED_STEPS_PER_S  # GPU seconds per world-step of this scene
    per_call = slope({r["worlds"]: r["step"] / r["step_calls"] for r in rows})[1]
    steps = big["step_calls"]  # batch steps (and forwards) of one episode, idle tail included
    per_sample = big["world_steps_per_sample"]
    window = 4 * GPU_WORLDS  # samples per window (`sim.warp.backend.WINDOW_BATCHES` batches)
    gpu_s = 0.0  # GPU time of one window: each family in batches of at most GPU_WORLDS
    for share in shares:
        members = round(share * window)
        for lo in range(0, members, GPU_WORLDS):
            gpu_s += steps * (per_call + min(GPU_WORLDS, members - lo) * world_step_s)
    host_s = (big["prepare"] + big["read"] + big["samples"]) / big["kept"]
    print("GPU PROJECTION (not measured):")
    print(f"  published: {PUBLISHED_STEPS_PER_S / 1e6:.2f} M steps/s, {PUBLISHED}")
    print(f"  this scene / humanoid per-world step cost on the CPU device: {ratio:.1f} x")
    print(f"  -> {1 / world_step_s / 1e3:.0f} k world-steps/s; {per_sample:.0f} per hand sample")
    hands = GPU_WORLDS / (steps * (per_call + GPU_WORLDS * world_step_s))
    print(f"  GPU, hand family in batches of {GPU_WORLDS}: {hands:.0f} samples/s")
    print(
        f"  GPU, default mix ({len(shares)} families, windows of {window}, launch overhead", end=""
    )
    print(f" {per_call * 1e3:.1f} ms per batch step): {window / gpu_s:.0f} samples/s")
    print(f"  host work {host_s * 1e3:.0f} ms per sample: {1 / host_s:.0f} samples/s per process")
    print(
        f"  projected: {min(window / gpu_s, 1 / host_s):.0f} samples/s with one host process; "
        f"the GPU saturates at about {host_s * window / gpu_s:.0f} processes (--workers)"
    )


def main(n_all: int = 32) -> None:
    timed("step", mjw, "step")
    timed("forward", mjw, "forward")
    c_backend(n_all)
    state = sampler.build_state(GenerateConfig(n=512))
    maker = JobMaker(state.ctx, "cpu", cache_size=256)
    hand_family(state, maker, 4)  # warm-up: kernels compile (cached afterwards)
    rows = [hand_family(state, maker, w) for w in (8, 32, 128)]
    print("warp CPU device, hand family (one batch of W worlds), CPU seconds:")
    print("  W     samples/CPU-s  (wall)   prepare   step    read    samples")
    for r in rows:
        print(
            f"  {r['worlds']:<5d} {r['rate']:8.2f}     ({r['wall_rate']:5.2f})  {r['prepare']:7.1f}"
            f" {r['step']:7.1f} {r['read']:7.1f} {r['samples']:7.1f}"
        )
    ours = slope({r["worlds"]: r["step"] / r["step_calls"] for r in rows})[0]
    humanoid = slope({w: humanoid_step_s(w) for w in (32, 128, 512)})[0]
    print(
        f"  per-world step cost: this scene {ours * 1e6:.0f} us, humanoid {humanoid * 1e6:.0f} us"
    )
    all_samples(n_all)
    projection(rows, ours, humanoid, family_shares(state, maker, 4 * n_all))


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 32)
