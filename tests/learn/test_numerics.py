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
    """The reference: without learn/, every thread keeps subnormals (so the next test can
    fail)."""
    plain = "from contextlib import nullcontext as flushing"
    if _subnormals_left(plain) != [1 << 24] * 3:
        pytest.skip("this CPU or torch build flushes subnormals already")


@pytest.mark.parametrize("module", ["learn.models", "learn.checkpoint", "learn.train"])
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


def test_check_script_counts_subnormals_from_bits(doc_script):
    """docs/check_subnormals.py counts what IEEE 754 calls subnormal, with the CPU's flush mode
    on (this process imported learn/, so float32 conversions here would zero them): against
    each value decoded from its fields by the standard's formula, in exact float64 arithmetic."""
    import numpy as np
    import torch

    script = doc_script("check_subnormals")
    # subnormal: the smallest, ~1e-38, a negative one, the largest; then 1.18e-38 (the smallest
    # normal), 1, +0, -0, inf, nan
    bits = [
        0x00000001,
        0x006CE3EE,
        0x80000100,
        0x007FFFFF,
        0x00800000,
        0x3F800000,
        0x00000000,
        0x80000000,
        0x7F800000,
        0x7FC00000,
    ]

    def value(b: int) -> float:  # IEEE 754 binary32, decoded in float64 (exact for these)
        sign, exponent, mantissa = -1.0 if b >> 31 else 1.0, (b >> 23) & 0xFF, b & 0x7FFFFF
        if exponent == 0xFF:
            return sign * float("inf") if mantissa == 0 else float("nan")
        if exponent == 0:
            return sign * mantissa * 2.0**-149
        return sign * (1 + mantissa / 2**23) * 2.0 ** (exponent - 127)

    expected = sum(1 for b in bits if 0 < abs(value(b)) < 2.0**-126)
    assert expected == 4
    weights = torch.from_numpy(np.array(bits, dtype=np.uint32).view(np.float32).copy())
    state = {"w": weights, "i": torch.arange(3), "z": torch.zeros(4)}
    assert script.subnormal_counts(state) == {"w": (expected, len(bits))}
