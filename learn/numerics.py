"""Subnormal floats flushed to zero while learn/'s networks run on the CPU, and only then.

Weight decay shrinks the weights of channels a network stops using by a factor each step, until
they are subnormal (below 1.2e-38 in float32); x86 arithmetic on subnormals is many times slower.
The 10x HandsNet's ``best.pt`` holds 70,794 of them (13 % of its last conv layer), and with them
kept its training step and CPU inference ran 3-6x slower than with them flushed (HandsNet
21.7-22.4 ms per image, flushed 3.84-6.29). Values that small carry no information there.

The mode (flush-to-zero and denormals-are-zero) belongs to each CPU thread:

- torch's worker threads inherit it when they start, so importing this module (``learn.models``
  and ``learn.checkpoint`` do) starts them with it, and they only ever run torch kernels;
- the calling thread also runs numpy, scipy, trimesh and MuJoCo code (``sim``, ``tactile``),
  which must keep IEEE 754 arithmetic (a KD-tree build in ``sim.contactors.placement`` crashed under
  the flush mode), so it flushes only inside :func:`flushing` (training epochs, evaluation,
  timing, prediction, int8 calibration and VGG16 features use it;
  ``tests/learn/test_flushing_paths.py`` checks each).

A program that starts torch's threads before importing ``learn`` keeps IEEE workers; call
``start_flushing_workers()`` first to change that.
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager

import torch

_local = threading.local()


def start_flushing_workers() -> None:
    """Start torch's CPU worker threads (when not yet running) in the flush mode; this thread
    leaves with IEEE arithmetic."""
    torch.set_flush_denormal(True)
    try:
        torch.ones(1 << 20).mul_(2.0).sum()  # a parallel operation: the pool starts here
    finally:
        torch.set_flush_denormal(False)


@contextmanager
def flushing() -> Iterator[None]:
    """Within the block, this thread flushes subnormal floats to zero; IEEE arithmetic after it
    (blocks nest). Also a decorator: ``@flushing()``."""
    depth = getattr(_local, "depth", 0)
    if depth == 0:
        torch.set_flush_denormal(True)
    _local.depth = depth + 1
    try:
        yield
    finally:
        _local.depth = depth
        if depth == 0:
            torch.set_flush_denormal(False)


start_flushing_workers()
