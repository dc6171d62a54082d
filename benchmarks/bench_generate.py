"""Dataset generation speed (samples/s) for 1 and 2 workers, and peak memory (RSS).

Runs `sim.generate.generate` on fresh temporary folders and prints wall time, samples/s, rejected
episodes by reason and the peak resident set size of this process and of its worker processes
(`resource.getrusage`, ru_maxrss in KiB on Linux). Timings on a shared machine are noisy.

Run: ``PYTHONPATH=. python benchmarks/bench_generate.py [n_samples] [part] [workers ...]``
(defaults: 256 samples of the forearm, workers 1 and 2).
"""

from __future__ import annotations

import resource
import sys
import tempfile
from pathlib import Path

from sim.gen_config import load_generate_config
from sim.generate import generate


def peak_rss_mib() -> tuple[float, float]:
    """(this process, largest finished child) peak resident set size, MiB."""
    own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    child = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    return own, child


def bench(n: int, part: str, workers: int) -> None:
    cfg = load_generate_config(None, n=n, part=part)
    with tempfile.TemporaryDirectory() as tmp:
        report = generate(cfg, Path(tmp) / "ds", workers=workers, progress=False)
    own, child = peak_rss_mib()
    print(
        f"{part}, {n} samples, workers {workers}: {report.wall_s:6.1f} s wall, "
        f"{report.samples_per_s:5.1f} samples/s; rejects {report.rejects}; peak RSS "
        f"parent {own:.0f} MiB, largest worker {child:.0f} MiB (so far)"
    )


def main(argv: list[str]) -> None:
    n = int(argv[0]) if argv else 256
    part = argv[1] if len(argv) > 1 else "forearm"
    for workers in [int(w) for w in argv[2:]] or [1, 2]:
        bench(n, part, workers)


if __name__ == "__main__":
    main(sys.argv[1:])
