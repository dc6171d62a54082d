"""Labelled samples per CPU-second on one core, as `handskin generate` makes them, with the split
of time between scene compilation, planning, stepping, skin readout and image making.

Two figures:
- *all samples*: samples 0..n-1 of the default forearm dataset (hands and non-hands in the
  paper's balance, every scene compiled as a fresh worker compiles it), through
  `sim.generate.sampler.sample_at`, the function each generator worker runs;
- *hands, scenes warm*: hand samples only, each subject's scene compiled beforehand (the figure
  earlier versions of this benchmark printed).

Times are CPU time of this process (`time.process_time`), so a machine loaded by other jobs
changes them little; wall time is printed beside. The part and its map are built before timing.

Run: ``OMP_NUM_THREADS=1 PYTHONPATH=. python benchmarks/bench_episodes.py [n_samples]``.
"""

from __future__ import annotations

import sys
import time
from collections import Counter

import numpy as np

from sim.contactors.subjects import sample_subjects
from sim.episode import press
from sim.episode import runner as episode
from sim.generate import hands as generate_hands
from sim.generate import sampler
from sim.generate.config import GenerateConfig
from sim.generate.hands import sample_hand

TARGET_PER_S = 100.0  # labelled samples per CPU-second on one core (the speed issue's target)
TIMERS: Counter = Counter()
ACTIVE: list[str] = []


def timed(name: str, module, attr: str) -> None:
    """Wrap module.attr so that its CPU time adds to TIMERS[name] (nested calls count once)."""
    fn = getattr(module, attr)

    def wrapper(*args, **kw):
        if ACTIVE:
            return fn(*args, **kw)
        ACTIVE.append(name)
        t0 = time.process_time()
        try:
            return fn(*args, **kw)
        finally:
            TIMERS[name] += time.process_time() - t0
            ACTIVE.pop()

    setattr(module, attr, wrapper)


def instrument() -> None:
    timed("compile scenes", press, "build_press_scene")
    timed("readout (depth, forces, pressure)", episode, "read_frame")
    timed("labels (attribution)", episode, "label_taxels")
    timed("images", episode, "tactile_images")


def timed_maker(make):
    """A press maker whose CPU time counts as planning."""
    box = type("Box", (), {"make": staticmethod(make)})
    timed("plan (contactor, placement, poses)", box, "make")
    return box.make


def report(title: str, n: int, cpu: float, wall: float, rejects: Counter) -> None:
    rate = n / cpu
    print(
        f"{title}: {n} samples in {cpu:.2f} s CPU: {rate:.1f} labelled samples per CPU-second "
        f"({rate / TARGET_PER_S:.2f} x the target {TARGET_PER_S:.0f}; wall {wall:.2f} s)"
    )
    rest = cpu - sum(TIMERS.values())
    for name, sec in [*TIMERS.items(), ("simulation (steps, controls) and the rest", rest)]:
        print(f"  {name:42s} {sec:6.2f} s  {100 * sec / cpu:5.1f} %")
    print(f"  rejected episodes: {dict(rejects)}")
    TIMERS.clear()


def all_samples(n: int) -> None:
    state = sampler.build_state(GenerateConfig(n=n))
    state.hand, state.nonhand = timed_maker(state.hand), timed_maker(state.nonhand)
    rejects: Counter = Counter()
    t0, w0 = time.process_time(), time.perf_counter()
    for i in range(n):
        rejects.update(sampler.sample_at(i, state)[1])
    report("all samples", n, time.process_time() - t0, time.perf_counter() - w0, rejects)
    return state.ctx


def warm_hands(n: int, ctx: episode.EpisodeContext) -> None:
    subjects = sample_subjects(10, np.random.default_rng(0))
    plain = generate_hands.hand_maker
    generate_hands.hand_maker = lambda *a, **kw: timed_maker(plain(*a, **kw))
    for i in range(len(subjects)):  # one compile per subject, outside the timing
        sample_hand(i, 1, ctx, subjects)
    TIMERS.clear()
    rejects: Counter = Counter()
    t0, w0 = time.process_time(), time.perf_counter()
    for i in range(n):
        rejects.update(sample_hand(i, 0, ctx, subjects)[1])
    report("hands, scenes warm", n, time.process_time() - t0, time.perf_counter() - w0, rejects)


def main(n: int = 100) -> None:
    instrument()
    ctx = all_samples(n)
    warm_hands(n, ctx)


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 100)
