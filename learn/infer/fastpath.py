"""The fast CPU inference path and time per image.

``fast_inference`` folds batch norm, feeds channels-last input and stores the weights in bfloat16
where this CPU has native bf16 and no decision but a near tie changes;
``cpu_ms_per_image`` and ``gpu_ms_per_image`` time a model at batch 1 after warm-up, as the
paper's Tables 3 and 8; ``interleaved_cpu_ms`` times several inference paths of one network
taking turns, so that a slow spell of a shared machine weighs on all of them alike.

    fast = fast_inference(model)                    # BN folded, channels-last, bf16 where safe
    ms = cpu_ms_per_image(fast, (68, 100), threads=1)
    eval_ms, fast_ms = interleaved_cpu_ms([model, fast], (68, 100), threads=1, rounds=3)
"""

from __future__ import annotations

import copy
import time

import numpy as np
import torch
import torch._inductor.config as inductor_config
from torch import nn

from learn.models import prepare_for_inference
from learn.numerics import flushing
from learn.train.device import bf16_supported
from tactile.errors import ConfigError

CHECK_SEED = 1234  # seed of the random images used to verify the bf16 path
BF16_TIE_GAP = 0.02  # top-two softmax gap under which a check decision is a tie, 0..1


class FastInference(nn.Module):
    """A prepared model (BN folded, channels-last weights) fed channels-last input, optionally
    with its weights stored in bfloat16 (cast once, not per call as autocast would); returns
    float32 logits. Keeps the wrapped model's attributes."""

    def __init__(self, prepared: nn.Module, bf16: bool) -> None:
        super().__init__()
        self.net = copy.deepcopy(prepared).to(torch.bfloat16) if bf16 else prepared
        self.bf16 = bf16
        for name in ("num_classes", "in_channels", "task", "input_size"):
            if hasattr(prepared, name):
                setattr(self, name, getattr(prepared, name))

    def forward(self, x: torch.Tensor):
        """``(B, C, H, W)`` → logits of the wrapped model, float32 (a tuple of them for a
        class-and-parts network)."""
        dtype = torch.bfloat16 if self.bf16 else torch.float32
        out = self.net(x.to(dtype).contiguous(memory_format=torch.channels_last))
        return tuple(o.float() for o in out) if isinstance(out, tuple) else out.float()


def clear_disagreements(a: nn.Module, b: nn.Module, x: torch.Tensor, tie_gap: float) -> int:
    """How many argmax decisions (images, or pixels of a segmenter) of ``a`` differ from ``b``'s
    on ``x`` ``(N, C, H, W)``, among those ``b`` takes clearly: its two largest softmax
    probabilities at least ``tie_gap`` apart (0 to 1). Near ties are not counted."""
    with torch.inference_mode():
        p = b(x).softmax(1)
        top2 = p.topk(2, dim=1).values
        clear = (top2[:, 0] - top2[:, 1]) >= tie_gap
        return int(((a(x).argmax(1) != p.argmax(1)) & clear).sum())


def fast_inference(
    model: nn.Module,
    *,
    bf16: bool | None = None,
    check: torch.Tensor | None = None,
    tie_gap: float = BF16_TIE_GAP,
) -> nn.Module:
    """The default CPU inference path: ``prepare_for_inference`` + channels-last input + bf16.

    bf16 (default: classifiers on CPUs with native bf16) is kept only if it changes no decision
    the float path takes on the ``check`` images (default: 32 seeded uniform random images)
    by a probability gap of ``tie_gap`` or more (`clear_disagreements`); otherwise the float
    path is returned. Near ties are left out: one among the check images (p = 0.497 against
    0.503) would otherwise turn bf16 off by the luck of which images are checked.
    """
    prepared = prepare_for_inference(model)
    if bf16 is None:
        bf16 = getattr(model, "task", "") == "classification" and bf16_supported()
    float_path = FastInference(prepared, False).eval()
    if not bf16:
        return float_path
    if check is None:
        size = getattr(model, "input_size", (68, 100))
        gen = torch.Generator().manual_seed(CHECK_SEED)
        check = torch.rand(32, getattr(model, "in_channels", 1), *size, generator=gen)
    fast = FastInference(prepared, True).eval()
    return fast if clear_disagreements(fast, float_path, check, tie_gap) == 0 else float_path


@flushing()
def time_per_image(
    model: nn.Module,
    input_size: tuple[int, int] = (68, 100),
    device: str | torch.device = "cpu",
    *,
    n_warmup: int = 10,
    n_runs: int = 50,
) -> float:
    """Median inference time per image in seconds, at batch size 1 after ``n_warmup`` runs, in
    eval mode under ``torch.inference_mode`` on a random ``(1, in_channels, H, W)`` input on
    ``device`` (CUDA synchronised around each run), with the caller's torch thread count."""
    device = torch.device(device)
    model = model.to(device).eval()
    x = torch.rand(1, getattr(model, "in_channels", 1), *input_size, device=device)
    sync = torch.cuda.synchronize if device.type == "cuda" else (lambda: None)
    times = []
    with torch.inference_mode():
        for i in range(n_warmup + n_runs):
            sync()
            start = time.perf_counter()
            model(x)
            sync()
            if i >= n_warmup:
                times.append(time.perf_counter() - start)
    return float(np.median(times))


def cpu_ms_per_image(
    model: nn.Module, input_size: tuple[int, int], threads: int = 1, n_runs: int = 100
) -> float:
    """Median CPU ms per image at batch 1 after warm-up, with ``threads`` torch threads."""
    before = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        return 1e3 * time_per_image(model, input_size, "cpu", n_warmup=20, n_runs=n_runs)
    finally:
        torch.set_num_threads(before)


MAX_THREADS = 1024  # torch threads a command may ask for (more overflows torch's own count)


def check_timing(time_runs: int, time_rounds: int, threads: int) -> None:
    """A ``ConfigError`` naming the option unless runs, rounds and threads are each >= 1 (and
    threads at most `MAX_THREADS`)."""
    for name, value in (
        ("time runs", time_runs),
        ("time rounds", time_rounds),
        ("threads", threads),
    ):
        if not isinstance(value, int) or value < 1:
            raise ConfigError(
                f"{name} must be a whole number >= 1, got {value!r}; fix the "
                f"timing options: pass --{name.replace(' ', '-')} 1 or more"
            )
    if threads > MAX_THREADS:
        raise ConfigError(f"--threads {threads} is out of range; allowed 1..{MAX_THREADS}")


def interleaved_cpu_ms(
    nets: list[nn.Module | None],
    input_size: tuple[int, int],
    threads: int = 1,
    n_runs: int = 100,
    rounds: int = 3,
    n_warmup: int = 10,
) -> list[float | None]:
    """CPU ms per image at batch 1 of each network (None for None): the least, over ``rounds``
    rounds, of the median of ``n_runs`` runs after ``n_warmup`` warm-up runs, the networks taking
    turns within each round. ``threads`` torch threads (restored afterwards); ``input_size``:
    (H, W) px. Raises ``ConfigError`` for fewer than one round, run or thread."""
    check_timing(n_runs, rounds, threads)
    if n_warmup < 0:
        raise ConfigError(f"warm-up runs must be >= 0, got {n_warmup}; fix the timing options")
    before = torch.get_num_threads()
    torch.set_num_threads(threads)
    best: list[float | None] = [None if n is None else float("inf") for n in nets]
    try:
        for _ in range(rounds):
            for i, net in enumerate(nets):
                if net is not None:
                    s = time_per_image(net, input_size, "cpu", n_warmup=n_warmup, n_runs=n_runs)
                    best[i] = min(best[i], 1e3 * s)
    finally:
        torch.set_num_threads(before)
    return best


def gpu_ms_per_image(model: nn.Module, input_size: tuple[int, int]) -> float | None:
    """Median GPU ms per image at batch 1 after warm-up, or None without CUDA."""
    if not torch.cuda.is_available():
        return None
    return 1e3 * time_per_image(copy.deepcopy(model), input_size, "cuda")


def compile_frozen(net: nn.Module, example: torch.Tensor) -> nn.Module:
    """``net`` (eval mode, float32, CPU) compiled by TorchInductor with its weights frozen into
    the graph, compiled now on ``example`` (B, C, H, W) at the current torch thread count; call
    it under ``torch.inference_mode()`` on inputs of that shape. The arithmetic is float32 as
    eval mode's, with fewer calls around it: what a stream of single frames gains. Compiling
    takes seconds and needs a C++ compiler; ConfigError saying why when it fails."""
    compiled = torch.compile(net.eval(), dynamic=False)
    try:
        with inductor_config.patch(freezing=True), torch.inference_mode(), flushing():
            compiled(example)
    except Exception as err:  # inductor raises many types: a missing compiler, a lowering, ...
        first = (str(err).strip().splitlines() or [""])[0][:200]
        raise ConfigError(
            f"torch.compile could not compile {type(net).__name__} ({type(err).__name__}: "
            f"{first}). Fix: run without --compile, or install a C++ compiler (g++)"
        ) from err
    return compiled
