"""8-bit integer inference for HandsNet: post-training static quantization with PyTorch's
FX graph mode (`torch.ao.quantization.quantize_fx`), calibrated on training images.

    net = quantize_int8(model, calib)     # calib (N, 1, h, w) float in [0, 1], N ≥ 16
    logits = net(x)                        # (B, 1, h, w) -> (B, num_classes) float32

Weights are 8-bit per output channel, activations 8-bit per tensor with ranges observed on the
calibration images (histogram observer, the backend's default). Batch norm is folded into the
convolutions and conv + ReLU fused before quantizing. The backend is oneDNN, the one with int8
kernels for AVX2-only CPUs (on an AMD EPYC without AVX-512 its HandsNet is about 1.5x faster
than the folded float model; fbgemm's is slower than float there). Only HandsNet: the VGG16
encoder's pooling returns indices, which FX quantization cannot observe, and SegNet's
unpooling has no quantized kernel.

Quantization changes the scores: ``handskin evaluate --int8`` reports the int8 network in a row
of its own, never in place of the float one.
"""

from __future__ import annotations

import contextlib
import copy
import warnings
from collections.abc import Iterator

import torch
import torch.fx.config as fx_config
from torch import nn
from torch.ao.quantization import QConfig, get_default_qconfig, get_default_qconfig_mapping
from torch.ao.quantization.observer import MinMaxObserver
from torch.ao.quantization.quantize_fx import convert_fx, prepare_fx

from learn.numerics import flushing
from tactile.errors import ConfigError

#: The quantized engine whose int8 kernels run on AVX2 CPUs (and on AVX-512 / AMX ones).
BACKEND = "onednn"
#: Fewest calibration images accepted (activation ranges from fewer are noise).
MIN_CALIBRATION = 16
#: Calibration batch size (images); the observers see every image once.
CALIBRATION_BATCH = 64


class Int8Classifier(nn.Module):
    """A quantized classifier: float ``(B, C, H, W)`` images in, float32 logits ``(B, K)`` out.

    Keeps the float model's ``num_classes``, ``in_channels``, ``task`` and ``input_size`` so the
    evaluation and timing code treat it like any network; ``int8`` is True.
    """

    int8 = True

    def __init__(self, body: nn.Module, like: nn.Module) -> None:
        super().__init__()
        self.body = body
        for name in ("num_classes", "in_channels", "task", "input_size"):
            if hasattr(like, name):
                setattr(self, name, getattr(like, name))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``(B, C, H, W)`` float → ``(B, num_classes)`` float32 logits."""
        size = getattr(self, "input_size", None)
        if size is not None and tuple(x.shape[-2:]) != tuple(size):
            raise ConfigError(
                f"int8 classifier built for input_size {tuple(size)} got images of "
                f"size {tuple(x.shape[-2:])}. Fix: resize the images"
            )
        return self.body(x.float().contiguous())


def int8_supported() -> bool:
    """True when this PyTorch build has the oneDNN quantized engine."""
    return BACKEND in torch.backends.quantized.supported_engines


@contextlib.contextmanager
def quantized_engine(name: str = BACKEND) -> Iterator[None]:
    """Set ``torch.backends.quantized.engine`` for the block, restoring the previous one."""
    before = torch.backends.quantized.engine
    torch.backends.quantized.engine = name
    try:
        yield
    finally:
        torch.backends.quantized.engine = before


def traceable_body(model: nn.Module) -> nn.Module:
    """HandsNet's ``features`` then ``classifier``, the part FX can trace (its forward checks
    the input size with Python control flow). ConfigError for any other network."""
    if type(model).__name__ != "HandsNet":
        raise ConfigError(
            f"int8 covers HandsNet, the real-time classifier, not {type(model).__name__} (the "
            "VGG16 encoder's pooling returns indices, which FX quantization cannot observe). "
            "Fix: a HandsNet checkpoint; other networks run in float (without --int8)"
        )
    return nn.Sequential(model.features, model.classifier)


def quantize_int8(model: nn.Module, calibration: torch.Tensor) -> Int8Classifier:
    """An int8 copy of a HandsNet (eval mode), its activation ranges observed on
    ``calibration`` (N, C, H, W) float images in [0, 1] (training images, N ≥ 16; the test split
    must not be used). ``model`` is not modified. ConfigError, before any work, for another network,
    too few or non-finite calibration images, or a PyTorch without the oneDNN engine."""
    body = traceable_body(model)
    if calibration.ndim != 4 or len(calibration) < MIN_CALIBRATION:
        raise ConfigError(
            f"int8 calibration needs at least {MIN_CALIBRATION} images (N, C, H, W); "
            f"got shape {tuple(calibration.shape)}. Fix: calibrate on more "
            "training images"
        )
    if not torch.isfinite(calibration).all():
        raise ConfigError(
            "int8 calibration images contain NaN or infinite values. Fix: pass images in [0, 1]"
        )
    if not int8_supported():
        raise ConfigError(
            f"this PyTorch build has no {BACKEND} quantized engine (it has "
            f"{torch.backends.quantized.supported_engines}). Fix: evaluate "
            "without --int8"
        )
    return Int8Classifier(_observed_and_converted(body, calibration), model).eval()


@contextlib.contextmanager
def _no_fx_stack_traces() -> Iterator[None]:
    """Skip FX's per-node Python stack traces while tracing (``torch.fx.config``): symbolizing
    them imports much of torch on first use, seconds per process, for debugging text only."""
    before = fx_config.do_not_emit_stack_traces
    fx_config.do_not_emit_stack_traces = True
    try:
        yield
    finally:
        fx_config.do_not_emit_stack_traces = before


def _observed_and_converted(
    body: nn.Module, calibration: torch.Tensor, qconfig_mapping=None
) -> nn.Module:
    """FX-quantized copy of ``body``, its activation ranges observed on ``calibration``
    (``qconfig_mapping``: the backend's default, histogram observers, when None)."""
    body = copy.deepcopy(body).eval()
    mapping = qconfig_mapping or get_default_qconfig_mapping(BACKEND)
    with quantized_engine(), _no_fx_stack_traces(), warnings.catch_warnings():
        # FX graph mode is deprecated in favour of torchao's pt2e flow, whose CPU int8 speed
        # needs torch.compile; the FX path runs eagerly with the same oneDNN kernels.
        warnings.simplefilter("ignore", (DeprecationWarning, FutureWarning, UserWarning))
        prepared = prepare_fx(body, mapping, (calibration[:1],))
        with torch.no_grad(), flushing():  # a trained net may hold subnormal weights
            for batch in calibration.split(CALIBRATION_BATCH):
                prepared(batch.float())
        return convert_fx(prepared)


def _skeleton_qconfig_mapping():
    """The backend's default mapping with a min/max global activation observer: the same
    quantized graph, dtypes and schemes as its histogram observer gives, without the range
    search (seconds per process), for a network whose ranges `load_int8_state` overwrites.
    HandsNet's layers all take the global entry."""
    weight = get_default_qconfig(BACKEND).weight
    fast = QConfig(activation=MinMaxObserver.with_args(reduce_range=False), weight=weight)
    return get_default_qconfig_mapping(BACKEND).set_global(fast)


def int8_skeleton(model: nn.Module) -> Int8Classifier:
    """An int8 network of ``model``'s architecture whose weights and ranges are placeholders,
    to be overwritten by `load_int8_state` (the quantized graph depends on the architecture
    only, not on the calibration images or the activation observer)."""
    body = traceable_body(model)
    h, w = getattr(model, "input_size", None) or (68, 100)
    ramp = torch.linspace(0, 1, h * w).reshape(1, 1, h, w).repeat(2, model.in_channels, 1, 1)
    net = _observed_and_converted(body, ramp, _skeleton_qconfig_mapping())
    return Int8Classifier(net, model).eval()


def load_int8_state(net: Int8Classifier, state: dict) -> Int8Classifier:
    """``net`` with the weights and activation ranges of ``state`` (``net.state_dict()`` of an
    int8 network of the same architecture). The weights are repacked under the oneDNN engine,
    as `quantize_int8` packs them, so the loaded network computes the same bits."""
    with quantized_engine():
        net.load_state_dict(state, strict=True)
    return net.eval()
