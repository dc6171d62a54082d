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

Quantization changes the scores: `handskin evaluate --int8` reports the int8 network in a row
of its own, never in place of the float one.
"""

from __future__ import annotations

import contextlib
import copy
import warnings
from collections.abc import Iterator
from pathlib import Path

import torch
from torch import nn

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
            f"int8 inference covers HandsNet, the real-time classifier; got "
            f"{type(model).__name__} (the VGG16 encoder's pooling returns indices, "
            "which FX quantization cannot observe). Fix: score or run it "
            "without --int8"
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
    import torch.fx.config as fx_config

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
    from torch.ao.quantization import get_default_qconfig_mapping
    from torch.ao.quantization.quantize_fx import convert_fx, prepare_fx

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
    from torch.ao.quantization import QConfig, get_default_qconfig, get_default_qconfig_mapping
    from torch.ao.quantization.observer import MinMaxObserver

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


#: Calibration images drawn from the training split by `calibration_images` (count).
N_CALIBRATION = 512


def calibration_images(
    data_path, run, hand_classes: tuple[str, ...] | None, n: int = N_CALIBRATION
) -> torch.Tensor:
    """``n`` images (n, 1, h, w) of the train split of a dataset or image folder, drawn by the
    run's seed, at the run's input size (``run``: the checkpoint's `RunConfig`)."""
    from learn.folder import materialize, open_split

    split = open_split(
        data_path,
        "train",
        run.task,
        run.model.input_size,
        hand_classes,
        run.train.seed,
        run.model.canvas_mm,
    )
    gen = torch.Generator().manual_seed(run.train.seed)
    pick = torch.randperm(len(split), generator=gen)[:n].sort().values
    return materialize(torch.utils.data.Subset(split, pick.tolist()), "int8 calibration").x


def calibration_source(ckpt: dict, calibration: str | Path | None = None) -> Path:
    """Where a checkpoint's int8 copy takes its calibration images: ``calibration`` (a dataset
    or image folder) or, if None, the data it was trained on (``ckpt["data"]["path"]``).
    ConfigError naming the fix when that is not on this machine."""
    recorded = (ckpt.get("data") or {}).get("path")
    where = Path(calibration) if calibration is not None else Path(recorded) if recorded else None
    if where is None or not where.exists():
        what = (
            f"--calibration {calibration} was not found"
            if calibration is not None
            else f"the checkpoint's training data {recorded} is not here"
            if recorded
            else "the checkpoint does not say what it was trained on"
        )
        raise ConfigError(
            f"int8 needs training images to set its activation ranges; {what}. "
            "Fix: pass --calibration DATASET (a dataset or image folder of the "
            "same skin; its train split is used)"
        )
    return where


def int8_from_checkpoint(
    model: nn.Module, run, ckpt: dict, calibration: str | Path | None = None
) -> Int8Classifier:
    """The int8 copy of a checkpoint's HandsNet ``model`` (``run``: its `RunConfig`, both from
    `learn.checkpoint.model_from_checkpoint`), calibrated on `N_CALIBRATION` images
    of the train split of `calibration_source`. An int8 file (``handskin quantize``,
    `learn.int8_file`) gives its saved network, calibrated when it was written. ConfigError,
    before the images are read, for another network, when the calibration data is not on this
    machine, or for ``calibration`` given with an int8 file."""
    from learn.int8_file import INT8_KEY, is_int8

    if is_int8(ckpt) and calibration is not None:
        raise ConfigError(
            "--calibration: this classifier is an int8 file, calibrated on "
            f"{ckpt[INT8_KEY]['calibration']['data']} when it was written. "
            "Fix: drop --calibration, or quantize its float checkpoint again "
            "with handskin quantize --calibration"
        )
    return int8_with_note(model, run, ckpt, calibration)[0]


def int8_with_note(
    model: nn.Module,
    run,
    ckpt: dict,
    calibration: str | Path | None = None,
    hand_classes: tuple[str, ...] | None = None,
) -> tuple[Int8Classifier, dict]:
    """`int8_from_checkpoint` and what a report says of its calibration (JSON-able: backend,
    image count, split; for an int8 file also its data and ``saved``). An int8 file gives its
    saved network and ``calibration`` is not read. ``hand_classes``: of an image folder
    (default: the checkpoint's)."""
    traceable_body(model)
    from learn.int8_file import calibration_note, int8_from_saved, is_int8

    if is_int8(ckpt):  # calibrated when it was written; ``calibration`` is not read
        return int8_from_saved(model, ckpt), calibration_note(ckpt)
    where = calibration_source(ckpt, calibration)
    hand = hand_classes or (ckpt.get("data") or {}).get("hand_classes")
    calib = calibration_images(where, run, hand and tuple(hand))
    note = {"backend": BACKEND, "calibration_images": len(calib), "calibration_split": "train"}
    return quantize_int8(model, calib), note
