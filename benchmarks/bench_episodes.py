"""Labelled hand samples per second on one core for the default forearm scene, with the split
of time between simulation, readout (depth, attribution, skin model, labels) and image making.

Times are CPU time of this process (`time.process_time`), so a machine loaded by other jobs does
not inflate them; wall time is printed beside.

Run: ``OMP_NUM_THREADS=1 PYTHONPATH=. python benchmarks/bench_episodes.py [n_samples]``.
"""

from __future__ import annotations

import sys
import time
from collections import Counter

import numpy as np

from sim import episode, generate_hands
from sim.generate_hands import sample_hand
from sim.subjects import sample_subjects

TIMERS: Counter = Counter()
ACTIVE: list[str] = []


def timed(name: str, module, attr: str) -> None:
    """Wrap module.attr so that its wall time adds to TIMERS[name]."""
    fn = getattr(module, attr)

    def wrapper(*args, **kw):
        if ACTIVE:  # nested call (label_image calls image): counted by the outer one
            return fn(*args, **kw)
        ACTIVE.append(name)
        t0 = time.process_time()
        try:
            return fn(*args, **kw)
        finally:
            TIMERS[name] += time.process_time() - t0
            ACTIVE.pop()

    setattr(module, attr, wrapper)


def main(n: int = 100) -> None:
    ctx = episode.EpisodeContext()
    subjects = sample_subjects(10, np.random.default_rng(0))
    for i in range(len(subjects)):  # warm the compiled-scene cache (one compile per subject)
        sample_hand(i, 1, ctx, subjects)
    timed("plan (placement, poses)", generate_hands, "plan_hand_interaction")
    timed("readout", episode, "read_frame")
    timed("labels", episode, "label_taxels")
    timed("images", episode, "tactile_images")
    rejects: Counter = Counter()
    t0, w0 = time.process_time(), time.perf_counter()
    for i in range(n):
        rejects.update(sample_hand(i, 0, ctx, subjects)[1])
    total, wall = time.process_time() - t0, time.perf_counter() - w0
    sim = total - sum(TIMERS.values())
    print(
        f"{n} samples in {total:.2f} s CPU: {n / total:.1f} labelled samples/s on one core "
        f"(wall {wall:.2f} s: {n / wall:.1f}/s)"
    )
    for name, sec in [("simulation (steps, controls, loop)", sim), *TIMERS.items()]:
        print(f"  {name:34s} {sec:6.2f} s  {100 * sec / total:5.1f} %")
    print(f"  rejects: {dict(rejects)}; frames read: 10 Hz over approach+load+hold")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 100)
