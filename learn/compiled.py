"""A network compiled by TorchInductor for CPU inference at batch 1, and its time per image.

``compile_for_cpu`` compiles a float inference path (``fast_inference(model, bf16=False)``:
batch norm folded, channels-last input, or any wrapper of it such as test-time flips or an
ensemble) with ``torch.compile``, its weights frozen into the graph and prepacked for oneDNN
(inductor's ``freezing``). The arithmetic is the same float32 as the prepared model's (outputs
agree to ~1e-7), the calls around it are fewer: on one core of the 2.5 GHz Xeon of
``docs/learning.md`` HandsNet goes from 3.4 to 2.8 ms per image, SegNet (width 0.25) from 12.4
to about 11.5 (``benchmarks/bench_models.py`` prints both on any machine).

    compiled = compile_for_cpu(fast_inference(model, bf16=False), torch.rand(1, 1, 68, 100))
    with torch.inference_mode():
        logits = compiled(x)                       # x: (1, 1, 68, 100), the example's shape
    ms, _ = compiled_ms_per_image(fast_inference(model, bf16=False), (68, 100), threads=1)

Compiling needs a C++ compiler and takes seconds (5-20 s the first time, a few seconds once
inductor's on-disk cache holds the kernels); it is a choice (``handskin evaluate --compile``),
not the default. A compiled network is specialised to its example's shape and thread count and
to inference mode: other inputs recompile it, without freezing. ``compile_for_cpu`` resets
torch's compiler first (torch falls back to eager code, silently, after 8 compilations of one
``forward``), so compiling another network makes an earlier compiled one recompile when next
called.
"""

from __future__ import annotations

import torch
import torch._inductor.config as inductor_config
from torch import nn

from learn.fastpath import interleaved_cpu_ms
from learn.numerics import flushing
from tactile.errors import HandskinError


class CompileUnavailable(HandskinError, RuntimeError):
    """``torch.compile`` could not compile the network here (no C++ compiler, an operation
    inductor cannot lower, ...); the message says why."""


def compile_for_cpu(net: nn.Module, example: torch.Tensor) -> nn.Module:
    """``net`` (eval mode, float32, CPU) compiled by TorchInductor with frozen weights, compiled
    now on ``example`` (``(B, C, H, W)`` float images) at the current torch thread count.

    Call the result under ``torch.inference_mode()`` with inputs of ``example``'s shape. Raises
    ``CompileUnavailable`` when compiling fails.
    """
    torch.compiler.reset()
    compiled = torch.compile(net.eval(), dynamic=False)
    try:
        with inductor_config.patch(freezing=True), torch.inference_mode(), flushing():
            compiled(example)
    except Exception as err:  # inductor raises many types: a missing compiler, a lowering, ...
        first = (str(err).strip().splitlines() or [""])[0][:200]
        raise CompileUnavailable(
            f"torch.compile could not compile {type(net).__name__} ({type(err).__name__}: "
            f"{first}); time the network without --compile, or install a C++ compiler (g++) "
            f"if that is what is missing"
        ) from err
    return compiled


def compiled_agreement(compiled: nn.Module, net: nn.Module, check: torch.Tensor) -> float:
    """Fraction of ``check`` images (``(N, C, H, W)``, run one at a time as the compiled network
    was compiled at batch 1) on which ``compiled``'s argmax (per image, or per pixel for
    segmenters) equals ``net``'s."""
    with torch.inference_mode(), flushing():
        same = [
            (compiled(x[None]).argmax(1) == net(x[None]).argmax(1)).double().mean() for x in check
        ]
    return float(torch.stack(same).mean())


def compile_at(net: nn.Module, input_size: tuple[int, int], threads: int = 1) -> nn.Module:
    """``compile_for_cpu`` of ``net`` on a batch-1 example of ``input_size`` (H, W) px, compiled
    at ``threads`` torch threads (the caller's count is restored). Raises
    ``CompileUnavailable``."""
    before = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        return compile_for_cpu(net, torch.rand(1, getattr(net, "in_channels", 1), *input_size))
    finally:
        torch.set_num_threads(before)


def compiled_ms_per_image(
    net: nn.Module,
    input_size: tuple[int, int],
    threads: int = 1,
    n_runs: int = 100,
    check: torch.Tensor | None = None,
) -> tuple[float, float | None]:
    """Median CPU ms per image at batch 1 after warm-up of ``net`` compiled by
    ``compile_for_cpu`` with ``threads`` torch threads (``input_size``: (H, W) px), and the
    fraction of ``check`` images (``(N, C, H, W)``, run one at a time) on which the compiled
    network's argmax (per image, or per pixel for segmenters) equals ``net``'s, None without
    ``check``. The compiled code is dropped afterwards. Raises ``CompileUnavailable``."""
    compiled = compile_at(net, input_size, threads)
    try:
        (ms,) = interleaved_cpu_ms([compiled], input_size, threads, n_runs, rounds=1, n_warmup=20)
        agree = (
            None if check is None or not len(check) else compiled_agreement(compiled, net, check)
        )
        return ms, agree
    finally:
        torch.compiler.reset()
