"""int8 HandsNet (`learn.quantize`): its logits follow the float network's within the 8-bit
steps, its calibration is what sets the activation ranges, bad input is refused before any
work, the process's quantized engine is left as it was, and `handskin evaluate --int8` adds a
row of its own to the report."""

from __future__ import annotations

import json

import pytest
import torch
import typer
from typer.testing import CliRunner

from learn.cli import register
from learn.data.load import materialize, open_split
from learn.evaluate.scoring import Job, evaluate_job
from learn.infer.int8_file import calibration_images
from learn.infer.quantize import MIN_CALIBRATION, int8_supported, quantize_int8
from learn.models import create_model
from learn.train.checkpoint import load_checkpoint, model_from_checkpoint
from tactile.errors import ConfigError

pytestmark = pytest.mark.skipif(
    not int8_supported(), reason="PyTorch without the oneDNN quantized engine"
)


def _images(n: int, seed: int, size=(32, 48)) -> torch.Tensor:
    """Sparse tactile-like images (n, 1, h, w) in [0, 1]: most pixels black."""
    gen = torch.Generator().manual_seed(seed)
    return torch.rand(n, 1, *size, generator=gen) ** 4


def _trained(checkpoints):
    model, run = model_from_checkpoint(load_checkpoint(checkpoints["handsnet"]))
    return model.eval(), run


def _relative_error(a: torch.Tensor, b: torch.Tensor) -> float:
    """Largest |a - b| over the spread of ``a`` (the float reference's logits)."""
    return float((a - b).abs().max() / (a.max() - a.min()))


def test_int8_follows_the_float_network(checkpoints, tiny_dataset):
    """On the held-out images the int8 network's logits stay within a few 8-bit steps of the
    float network's (256 levels per activation range: 4 % of the logit spread allows ~10
    steps accumulated over 7 layers) and its decisions agree on all but borderline images."""
    model, run = _trained(checkpoints)
    calib = calibration_images(tiny_dataset, run, None)
    test = materialize(
        open_split(tiny_dataset, "test", run.task, run.model.input_size, None, run.train.seed),
        progress=False,
    )
    q = quantize_int8(model, calib)
    with torch.no_grad():
        ref, got = model(test.x), q(test.x)
    assert got.dtype == torch.float32 and got.shape == ref.shape
    assert _relative_error(ref, got) < 0.04
    margin = (ref[:, 1] - ref[:, 0]).abs()
    clear = margin > 0.1 * (ref.max() - ref.min())  # not a near-tie in the float network
    assert clear.sum() >= len(ref) // 2
    assert torch.equal(ref[clear].argmax(1), got[clear].argmax(1))


def test_calibration_sets_the_activation_ranges(checkpoints, tiny_dataset):
    """Calibrated on images 100x darker than those it then sees, the int8 network clips its
    activations and misses by far more than when calibrated on the training images."""
    model, run = _trained(checkpoints)
    calib = calibration_images(tiny_dataset, run, None)
    x = materialize(
        open_split(tiny_dataset, "test", run.task, run.model.input_size, None, run.train.seed),
        progress=False,
    ).x
    with torch.no_grad():
        ref = model(x)
        good = _relative_error(ref, quantize_int8(model, calib)(x))
        bad = _relative_error(ref, quantize_int8(model, calib * 0.01)(x))
    assert bad > 5 * good


def test_model_and_engine_untouched():
    torch.manual_seed(0)
    model = create_model("handsnet", input_size=(32, 48)).eval()
    before = {k: v.clone() for k, v in model.state_dict().items()}
    engine = torch.backends.quantized.engine
    q = quantize_int8(model, _images(16, 0))
    assert torch.backends.quantized.engine == engine
    assert all(torch.equal(before[k], v) for k, v in model.state_dict().items())
    assert q.num_classes == 2 and q.input_size == (32, 48) and q.task == "classification"
    with pytest.raises(ConfigError, match="input_size"):
        q(torch.zeros(1, 1, 40, 48))


@pytest.mark.parametrize(
    ("case", "message"),
    [
        ("segnet", "covers HandsNet"),
        ("vgg16", "covers HandsNet"),
        ("few", f"at least {MIN_CALIBRATION} images"),
        ("nan", "NaN"),
    ],
)
def test_bad_input_refused(case, message):
    kw = {"width": 0.125} if case in ("segnet", "vgg16") else {"input_size": (32, 48)}
    model = create_model(case if case in ("segnet", "vgg16") else "handsnet", **kw).eval()
    calib = _images(MIN_CALIBRATION - 1 if case == "few" else 32, 0)
    if case == "nan":
        calib[3, 0, 5, 5] = float("nan")
    with pytest.raises(ConfigError, match=message):
        quantize_int8(model, calib)


def test_evaluate_int8_row(checkpoints, tiny_dataset, tmp_path):
    """``handskin evaluate --int8``: the float row and a ``HandsNet int8`` row right after it,
    scored on the same test images, calibrated on the train split; refused, with nothing
    written, when no HandsNet is given."""
    app = typer.Typer()
    register(app)
    runner = CliRunner()
    md = tmp_path / "r.md"
    res = runner.invoke(
        app,
        ["evaluate", str(tiny_dataset), str(checkpoints["segnet"]), "--out", str(md), "--int8"],
    )
    assert res.exit_code == 2 and "no float HandsNet checkpoint" in res.output, res.output
    assert not md.exists()
    res = runner.invoke(
        app,
        ["evaluate", str(tiny_dataset), str(checkpoints["handsnet"]), "--out", str(md), "--int8"],
    )
    assert res.exit_code == 0, res.output
    rows = json.loads(md.with_suffix(".json").read_text())
    plain, q = rows
    assert plain["int8"] is None and q["int8"]["backend"] == "onednn"
    n_train = len(open_split(tiny_dataset, "train", "classify", (32, 48), None, 0))
    assert q["int8"]["calibration_images"] == min(n_train, 512)
    assert q["n_test"] == plain["n_test"]
    table = md.read_text().split("## Hand / non-hand")[1].split("##")[0]
    lines = [ln for ln in table.splitlines() if ln.startswith("| HandsNet")]
    assert [ln.split(" | ")[0] for ln in lines] == ["| HandsNet", "| HandsNet, int8"]
    assert "int8 (onednn; activation ranges from" in md.read_text()
    direct = evaluate_job(Job((checkpoints["handsnet"],), int8=True), tiny_dataset, time_runs=3)
    assert direct["cm"] == q["cm"]  # calibration drawn by the run's seed: the same network


def test_predict_int8(checkpoints, tiny_dataset, tmp_path):
    """``handskin predict --int8``: the int8 classifier is the one ``evaluate --int8`` scores
    (calibrated on the checkpoint's training data by default, or on ``--calibration``), so its
    probability for a sample is that network's softmax; bad combinations and a missing
    calibration set are refused before any picture is written."""
    from learn.infer.predict import load_predictor, read_sample

    app = typer.Typer()
    register(app)
    runner = CliRunner()
    hn = str(checkpoints["handsnet"])
    png = tmp_path / "p.png"
    # sample 33: a non-hand whose float and int8 probabilities differ (0.822 / 0.833)
    base = ["predict", str(tiny_dataset), "--sample", "33", "--png", str(png)]
    for extra, message in (
        (["--classifier", hn, "--calibration", str(tiny_dataset)], "add --int8"),
        (["--segmenter", str(checkpoints["segnet"]), "--int8"], "give --classifier"),
        (["--classifier", hn, "--int8", "--calibration", str(tmp_path / "nope")], "not found"),
        (["--classifier", str(checkpoints["segnet"]), "--int8"], "covers HandsNet"),
    ):
        res = runner.invoke(app, base + extra)
        assert res.exit_code == 2 and message in res.output, res.output
        assert not png.exists()
    moved = load_checkpoint(checkpoints["handsnet"])  # trained on data no longer on this machine
    moved["data"] = {**moved["data"], "path": str(tmp_path / "gone")}
    torch.save(moved, tmp_path / "moved.pt")
    res = runner.invoke(app, [*base, "--classifier", str(tmp_path / "moved.pt"), "--int8"])
    assert res.exit_code == 2 and "is not here" in res.output and not png.exists(), res.output
    res = runner.invoke(app, [*base, "--classifier", hn, "--int8"])
    assert res.exit_code == 0, res.output
    printed = float(res.output.split("(probability ")[1].split(")")[0])
    # the reference: evaluate's int8 network (same calibration draw), run on the stored image
    model, run = _trained(checkpoints)
    q = quantize_int8(model, calibration_images(tiny_dataset, run, None))
    sample = read_sample(tiny_dataset, 33)
    x = _input_of(load_predictor(checkpoints["handsnet"]), sample.image)
    with torch.no_grad():
        ref = q(x)[0]
    assert abs(printed - float(torch.softmax(ref, 0).max())) < 1e-4  # printed with 4 decimals
    explicit = load_predictor(checkpoints["handsnet"], int8=True, calibration=tiny_dataset)
    assert torch.equal(explicit.logits(sample.image), ref)


def _input_of(predictor, image) -> torch.Tensor:
    """(1, 1, h, w) network input of a stored (H, W) uint8 image (`learn.inputs.net_input`)."""
    import numpy as np

    from learn.inputs import net_input

    arr = net_input(
        np.asarray(image, np.uint8),
        predictor.input_size,
        predictor.task,
        predictor.canvas(1.0),
    )
    return torch.from_numpy(arr)[None, None]
