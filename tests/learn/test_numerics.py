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
