"""learn.numerics: subnormal floats flushed to zero in torch's worker threads and inside
`flushing` blocks; IEEE arithmetic elsewhere on the calling thread."""

import subprocess
import sys

import pytest

# 2**24 float32 subnormals, built from their bits (a float conversion would flush them on a
# flushing thread), times one on 2 torch threads; under IEEE 754 gradual underflow every product
# stays subnormal, under flush-to-zero / denormals-are-zero it is 0. Prints the subnormals left
# by torch outside flushing(), inside it, and by numpy after it.
PRODUCT = """
import numpy as np
torch.set_num_threads(2)
bits = np.full(1 << 24, 0x100, dtype=np.uint32)
x = torch.from_numpy(bits.view(np.float32))
left = lambda y: int((y.view(torch.int32) != 0).sum())
outside = left(x * 1.0)
with flushing():
    inside = left(x * 1.0)
print(outside, inside, int(((bits.view(np.float32) * np.float32(1)).view(np.uint32) != 0).sum()))
"""


def _subnormals_left(prelude: str) -> list[int]:
    code = f"{prelude}\nimport torch\n{PRODUCT}"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return [int(v) for v in out.stdout.split()]


def test_plain_torch_keeps_subnormals():
    """The reference: without learn/, every thread keeps subnormals (IEEE 754 gradual
    underflow), so the next test's flushing is learn/'s doing."""
    plain = "from contextlib import nullcontext as flushing"
    assert _subnormals_left(plain) == [1 << 24] * 3


@pytest.mark.parametrize("module", ["learn.models", "learn.train.checkpoint", "learn.train.loop"])
def test_importing_learn_flushes_in_workers_and_within_flushing_only(module):
    """After importing learn/, torch's worker thread flushes (some products are 0 even outside
    ``flushing``), the calling thread only inside ``flushing`` (all are 0 there), and numpy on
    the calling thread keeps IEEE arithmetic after it (sim/ and tactile/ rely on it)."""
    outside, inside, numpy_after = _subnormals_left(
        f"import {module}\nfrom learn.numerics import flushing"
    )
    assert 0 < outside < 1 << 24
    assert inside == 0
    assert numpy_after == 1 << 24


def test_flushing_nests_and_restores():
    """IEEE arithmetic is back only when the outermost block ends."""
    import numpy as np

    from learn.numerics import flushing

    sub = np.array([0x100], dtype=np.uint32).view(np.float32)

    def kept() -> bool:
        return bool((sub * np.float32(1)).view(np.uint32)[0])

    assert kept()
    with flushing():
        with flushing():
            assert not kept()
        assert not kept()
    assert kept()
