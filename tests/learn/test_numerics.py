"""learn/ flushes subnormal floats to zero (learn.numerics), in torch's worker threads too."""

import subprocess
import sys

import pytest

# 2**22 float32 subnormals (1e-39) times one, on 2 torch threads: under IEEE 754 gradual underflow
# every product stays 1e-39; with flush-to-zero / denormals-are-zero every one is 0.
PRODUCT = ("torch.set_num_threads(2); x = torch.full((1 << 22,), 1e-39) * 1.0; "
           "print(int(x.count_nonzero()))")  # fmt: skip


def _nonzero(prelude: str) -> int:
    code = f"{prelude}; import torch; {PRODUCT}"
    return int(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                              check=True).stdout)  # fmt: skip


def test_plain_torch_keeps_subnormals():
    """The reference: without learn/, the CPU keeps subnormals (so the next test can fail)."""
    if _nonzero("import numpy") != 1 << 22:
        pytest.skip("this CPU or torch build flushes subnormals already")


@pytest.mark.parametrize("module", ["learn.models", "learn.checkpoint", "learn.train"])
def test_importing_learn_flushes_subnormals(module):
    assert _nonzero(f"import {module}") == 0


def test_check_script_counts_subnormals_from_bits():
    """docs/check_subnormals.py counts what IEEE 754 calls subnormal, with the CPU's flush mode
    on (this process imported learn/, so float32 conversions here would zero them): against
    each value decoded from its fields by the standard's formula, in exact float64 arithmetic."""
    import importlib.util
    from pathlib import Path

    import numpy as np
    import torch

    path = Path(__file__).resolve().parents[2] / "docs" / "check_subnormals.py"
    spec = importlib.util.spec_from_file_location("check_subnormals", path)
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    # subnormal: the smallest, ~1e-38, a negative one, the largest; then 1.18e-38 (the smallest
    # normal), 1, +0, -0, inf, nan
    bits = [0x00000001, 0x006CE3EE, 0x80000100, 0x007FFFFF,
            0x00800000, 0x3F800000, 0x00000000, 0x80000000, 0x7F800000, 0x7FC00000]  # fmt: skip

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
