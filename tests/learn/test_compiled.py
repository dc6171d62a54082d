"""The TorchInductor-compiled inference path (`learn.compiled`): the compiled networks compute the
eager networks' logits, every compile really compiles, a missing compiler is a clear error, and
`handskin evaluate --compile` times it and shows it in the report only when it is faster and
agrees with the fast path."""

from __future__ import annotations

import pytest
import torch
import torch._dynamo.config as dynamo_config
import torch._inductor.config as inductor_config
from torch import nn
from torch._dynamo.utils import counters

from learn.compiled import CompileUnavailable, compile_for_cpu, compiled_ms_per_image
from learn.eval_report import _best_ms, _timing, write_report
from learn.evaluate import evaluate_checkpoint
from learn.fastpath import fast_inference
from learn.models import create_model

SIZE = (68, 100)


def sparse_images(n: int, seed: int) -> torch.Tensor:
    """``(n, 1, 68, 100)`` images in [0, 1], mostly near black as tactile images are."""
    return torch.rand(n, 1, *SIZE, generator=torch.Generator().manual_seed(seed)) ** 6


@pytest.mark.parametrize("arch", ["handsnet", "segnet"])
def test_compiled_network_computes_the_eager_logits(arch):
    torch.manual_seed(0)
    kw = {"input_size": SIZE} if arch == "handsnet" else {"width": 0.125}
    model = create_model(arch, **kw)
    model.train()
    with torch.no_grad():  # batch-norm statistics away from the identity, so folding matters
        model(sparse_images(16, 1))
    model.eval()
    x = sparse_images(3, 2)
    compiled = compile_for_cpu(fast_inference(model, bf16=False), x[:1])
    with torch.inference_mode():
        for image in x:  # the reference: the eager network, batch norm unfolded
            want, got = model(image[None]), compiled(image[None])
            assert got.shape == want.shape
            torch.testing.assert_close(got, want, rtol=1e-4, atol=1e-4 * float(want.abs().max()))


def tiny_net(seed: int) -> nn.Module:
    torch.manual_seed(seed)
    return nn.Sequential(nn.Conv2d(1, 4, 3), nn.ReLU(), nn.Flatten(), nn.Linear(144, 2)).eval()


def test_every_compile_compiles_a_graph():
    """torch runs a forward in eager code, silently, past its recompile limit; compile_for_cpu
    resets the compiler, so the third network of a class past a limit of 1 still compiles."""
    x = torch.rand(1, 1, 8, 8)
    with dynamo_config.patch(recompile_limit=1):
        new_graphs = []
        for seed in range(3):
            net = tiny_net(seed)
            before = counters["stats"]["unique_graphs"]
            compiled = compile_for_cpu(net, x)
            new_graphs.append(counters["stats"]["unique_graphs"] - before)
            with torch.inference_mode():
                torch.testing.assert_close(compiled(x), net(x))
    assert new_graphs == [1, 1, 1]


def test_missing_compiler_is_a_clear_error():
    broken = {"cpp.cxx": (None, "/nonexistent/g++"), "fx_graph_cache": False}
    with inductor_config.patch(broken), pytest.raises(CompileUnavailable) as err:
        compile_for_cpu(tiny_net(9), torch.rand(1, 1, 8, 8))
    assert "C++ compiler" in str(err.value) and "without --compile" in str(err.value)


def test_compiled_ms_per_image_times_and_checks():
    threads = torch.get_num_threads()
    model = create_model("handsnet", input_size=SIZE).eval()
    ms, agree = compiled_ms_per_image(
        fast_inference(model, bf16=False), SIZE, 1, 5, sparse_images(6, 3)
    )
    assert 0 < ms < 1e3 and agree == 1.0
    assert torch.get_num_threads() == threads


def row(fast: float, compiled: float | None, agree: float | None, note: str | None = None):
    ms = {"eval_mode": 9.0, "prepared": 8.0, "fast": fast, "compiled": compiled, "gpu": None}
    return {
        "ms_per_image": ms,
        "compiled_agreement": agree,
        "compile_note": note,
        "threads": 1,
        "bf16": False,
    }


def test_tables_show_the_compiled_time_only_when_faster_and_agreeing():
    assert _best_ms(row(3.4, 2.8, 1.0)) == "2.80 (compiled)"
    assert _best_ms(row(3.4, 2.8, None)) == "2.80 (compiled)"
    assert _best_ms(row(3.4, 3.6, 1.0)) == "3.40"  # slower
    assert _best_ms(row(3.4, 2.8, 0.99)) == "3.40"  # other predictions
    assert _best_ms(row(3.4, None, None)) == "3.40"  # not asked
    old = row(3.4, None, None)  # a report row of an earlier version: no compiled fields
    del old["ms_per_image"]["compiled"], old["compiled_agreement"], old["compile_note"]
    assert _best_ms(old) == "3.40" and "compiled" not in _timing(old)
    assert "compiled: not timed (no g++)" in _timing(row(3.4, None, None, "no g++"))


def test_evaluate_compiled(checkpoints, tiny_dataset, tmp_path):
    plain = evaluate_checkpoint(checkpoints["handsnet"], tiny_dataset, time_runs=3)
    assert plain["ms_per_image"]["compiled"] is None and plain["compile_note"] is None
    got = evaluate_checkpoint(checkpoints["handsnet"], tiny_dataset, time_runs=3, compiled=True)
    assert got["ms_per_image"]["compiled"] > 0 and got["compiled_agreement"] == 1.0
    assert got["metrics"] == plain["metrics"]
    text = write_report([got], tmp_path / "report.md", "tiny").read_text()
    assert "compiled (torch.compile, frozen weights)" in text
