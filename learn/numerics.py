"""CPU float mode of every process that runs learn/'s networks: subnormal floats flushed to zero.

Weight decay shrinks the weights of channels a network stops using by a factor each step, until
they are subnormal (below 1.2e-38 in float32); x86 arithmetic on subnormals is many times slower.
The 10x HandsNet's ``best.pt`` holds 71,000 of them (13 % of its last conv layer), and without
flushing its training step and CPU inference ran 4-6x slower than with it
(``docs/learning.md``, "Subnormal weights"). Values that small carry no information here.

Importing this module (``learn.models`` and ``learn.checkpoint`` do) sets flush-to-zero and
denormals-are-zero for the importing thread. Threads inherit the mode when they start, so torch's
CPU worker threads get it when this runs before torch's first parallel operation, as it does for
``handskin`` and any program that imports ``learn`` before computing with torch; threads already
running keep their mode (call ``flush_denormals`` earlier in such a program).
"""

from __future__ import annotations

import torch


def flush_denormals() -> bool:
    """Flush subnormal floats to zero on this CPU thread and the threads it starts later; False
    where the CPU has no such mode (then nothing changes)."""
    return bool(torch.set_flush_denormal(True))


FLUSHING = flush_denormals()
