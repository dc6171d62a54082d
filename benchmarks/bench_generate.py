"""Dataset generation speed (samples/s) for 1 and 2 workers, peak memory (RSS), the time to
refuse a folder of another configuration, and `sim.generate.tiny.tiny_samples`' time for 8 samples.

Runs `sim.generate.run.generate` on fresh temporary folders and prints wall time, samples/s,
rejected episodes by reason and the peak resident set size of this process and of its worker
processes (`resource.getrusage`, ru_maxrss in KiB on Linux). Timings on a shared machine are noisy.

Run: ``PYTHONPATH=. python benchmarks/bench_generate.py [n_samples] [part] [workers ...]``
(defaults: 256 samples of the forearm, workers 1 and 2).
"""

from __future__ import annotations

import resource
import sys
import tempfile
import time
from pathlib import Path

from sim.generate.config import load_generate_config
from sim.generate.run import generate
from sim.generate.tiny import tiny_map, tiny_samples
from tactile.errors import DataError


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


def bench_refusal(part: str) -> None:
    """Seconds until `generate` refuses a folder holding a dataset of another seed."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "ds"
        generate(load_generate_config(None, n=4, part=part), out, workers=1, progress=False)
        t0 = time.perf_counter()
        try:
            generate(load_generate_config(None, n=4, part=part, seed=1), out, progress=False)
        except DataError:
            pass
        print(
            f"{part}: folder of another configuration refused in {time.perf_counter() - t0:.2f} s"
        )


def bench_tiny(n: int = 8) -> None:
    """Seconds of `tiny_samples(n)` once the tiny part and map are built."""
    tiny_map()
    t0 = time.perf_counter()
    tiny_samples(n=n, seed=0)
    print(f"tiny_samples({n}): {time.perf_counter() - t0:.2f} s after the part is built")


def main(argv: list[str]) -> None:
    n = int(argv[0]) if argv else 256
    part = argv[1] if len(argv) > 1 else "forearm"
    bench_tiny()
    bench_refusal(part)
    for workers in [int(w) for w in argv[2:]] or [1, 2]:
        bench(n, part, workers)


if __name__ == "__main__":
    main(sys.argv[1:])
