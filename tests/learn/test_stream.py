"""The frame path of `learn.infer.stream` and `handskin stream`, checked against the reference
path: `tactile.TactileMap.image`, `learn.inputs.net_input`, `tactile.images.labels.backproject` and
`learn.infer.predict.predict_frame`, on the tiny dataset's frames, over standard input and a
loopback ZeroMQ socket."""

from __future__ import annotations

import io
import json
import socket
import subprocess
import sys
import threading

import numpy as np
import pytest
import torch

from learn.infer.frame import ImageOps, InputOps, TaxelVotes
from learn.infer.predict import Predictor, load_map, load_predictor, predict_frame
from learn.infer.serve import FrameDecoder, serve
from learn.infer.stream import Recognizer
from learn.inputs import labels_on_map, net_input
from tactile.dataset import open_dataset
from tactile.errors import ConfigError, DataError
from tactile.images.labels import backproject

SIZE = (32, 48)  # the tiny checkpoints' input, px


@pytest.fixture(scope="module")
def frames(tiny_dataset):
    """(map, layout, to_pa, raw (B, N) counts): the tiny set's frames, then an empty one."""
    tmap, layout, to_pa = load_map(tiny_dataset)
    raw = open_dataset(tiny_dataset).raw[:]
    return tmap, layout, to_pa, np.vstack([raw, np.zeros_like(raw[:1])])


@pytest.fixture(scope="module")
def predictors(checkpoints):
    torch.set_num_threads(1)
    return load_predictor(checkpoints["handsnet"]), load_predictor(checkpoints["segnet"])


def edge_frames(tmap, n: int = 20) -> np.ndarray:
    """Seeded frames of 1 to 40 random taxels, some at the map's edges, some negative."""
    rng = np.random.default_rng(5)
    out = np.zeros((n, tmap.n_taxels))
    for f in out:
        taxels = rng.choice(tmap.n_taxels, rng.integers(1, 40), replace=False)
        f[taxels] = rng.uniform(-50, 900, len(taxels))
    return out


def test_image_on_the_box_is_the_map_image(frames):
    tmap, _, to_pa, raw = frames
    pix = ImageOps.build(tmap)
    image, box = np.full(tmap.shape, 0, np.uint8), None
    for p in [*edge_frames(tmap), *to_pa(raw)]:  # one buffer: each frame clears the last box
        box = pix.fill(p, image, box)
        assert np.array_equal(image, tmap.image(p))
    assert box is None  # the last frame pressed nothing


@pytest.mark.parametrize("canvas", [None, (40, 120), (90, 60)])
def test_network_inputs_are_net_inputs(frames, canvas):
    tmap, _, to_pa, raw = frames
    ops = InputOps.build(tmap, SIZE, canvas)
    pix = ImageOps.build(tmap)
    ext = np.zeros(tmap.shape[0] * tmap.shape[1] + 1, np.uint8)
    image = ext[1:].reshape(tmap.shape)
    resized, kept, box = np.zeros(SIZE, np.float32), np.zeros(SIZE, np.float32), None
    for p in [*to_pa(raw), *edge_frames(tmap)]:
        box = pix.fill(p, image, box)
        ops.resize(image, box, resized)
        ops.keep_support(resized, ext, box, kept)
        # exact by construction (tactile.images.resize.resize_grey): the same bytes on any CPU
        assert np.array_equal(resized, net_input(image, SIZE, "classify", canvas))
        assert np.array_equal(kept, net_input(image, SIZE, "segment", canvas))


@pytest.mark.parametrize("canvas", [None, (40, 120)])
def test_votes_are_the_back_projection(frames, canvas):
    tmap, _, to_pa, raw = frames
    ops = InputOps.build(tmap, SIZE, canvas)
    votes = TaxelVotes.build(tmap, ops)
    rng = np.random.default_rng(2)
    pix = ImageOps.build(tmap)
    for p in [*to_pa(raw[::4]), *edge_frames(tmap, 5)]:
        image = tmap.image(p)
        labels = rng.integers(0, 7, SIZE).astype(np.uint8)
        labels[rng.random(SIZE) < 0.3] = 0
        segmentation = np.where(image > 0, labels_on_map(labels, tmap.shape, canvas), 0)
        got = votes.labels(np.r_[0, labels.ravel()], np.r_[0, image.ravel()], pix.box(p))
        assert np.array_equal(got, backproject(tmap, segmentation))


def check_answer(answer: dict, ref, labels: bool = True) -> None:
    """``answer`` (a stream's JSON object) says what ``ref`` (`predict_frame`) says."""
    assert answer["class"] == ref.class_name
    assert answer["probability"] == pytest.approx(ref.probability, abs=2e-6)
    parts = {
        k: {"taxels": s.n_taxels, "mean_pa": round(s.mean_pressure, 3)}
        for k, s in ref.parts.items()
    }
    assert answer["parts"] == parts
    if labels:
        assert answer["taxel_labels"] == ref.taxel_labels.tolist()


@pytest.mark.parametrize("canvas_mm", [None, (40.0, 120.0)])
def test_recognizer_answers_as_predict_frame(frames, predictors, canvas_mm):
    tmap, _, to_pa, raw = frames
    clf, seg = (
        Predictor(p.model, p.task, p.input_size, p.class_names, canvas_mm) for p in predictors
    )
    rec = Recognizer(tmap, clf, seg, threshold_pa=100.0)
    hands = 0
    for p in to_pa(raw):
        answer, ref = rec.step(p), predict_frame(p, tmap, clf, seg, threshold_pa=100.0)
        check_answer(answer.as_json(), ref)
        assert answer.parts == ref.parts and answer.latency_ms > 0
        x = net_input(ref.image, SIZE, "segment", seg.canvas(1.0))
        net = seg.logits(ref.image, tmap.step_mm).argmax(0).numpy() * (x > 0)
        assert np.array_equal(answer.segmentation, net)
        hands += answer.class_name == "hand" and answer.taxel_labels.any()
    assert hands >= 5  # the comparison saw segmented hands


def test_recognizer_alone_and_errors(frames, predictors):
    tmap, _, to_pa, raw = frames
    clf, seg = predictors
    only_clf, only_seg = Recognizer(tmap, clf), Recognizer(tmap, None, seg)
    p = to_pa(raw[0])
    ref = predict_frame(p, tmap, clf, seg)
    assert only_clf.step(p).class_name == ref.class_name and only_clf.step(p).parts is None
    assert np.array_equal(only_seg.step(p).taxel_labels, ref.taxel_labels)
    with pytest.raises(DataError, match=f"a frame of 5 values; the map has {tmap.n_taxels}"):
        only_clf.step(np.ones(5))
    with pytest.raises(DataError, match="taxel 3 of the frame is nan; give finite pressures"):
        only_clf.step(np.where(np.arange(tmap.n_taxels) == 3, np.nan, p))
    with pytest.raises(ConfigError, match="give a classifier, a segmenter or both"):
        Recognizer(tmap)
    with pytest.raises(ConfigError, match="the segmenter is a 'classify' network"):
        Recognizer(tmap, None, clf)


def test_serve_counts_drops_late_answers_and_errors(frames, predictors):
    tmap, layout, to_pa, raw = frames
    rec = Recognizer(tmap, *predictors)
    lines = [",".join(map(str, r)).encode() for r in raw[:6]]
    lines[1], lines[2] = b"1,x,3", b"1,2,3"
    lines[4] = json.dumps([float("nan"), *raw[4][1:].tolist()]).encode()
    batches = iter([[(0.0, lines[0])], [(0.0, line) for line in lines[1:5]], [(0.0, lines[5])]])
    sent: list[dict] = []
    stats = serve(rec, FrameDecoder(layout, to_pa), lambda: next(batches, None), sent.append)
    assert [a["frame"] for a in sent] == list(range(6))
    assert sent[1]["error"].startswith("not a frame: '1,x,3'")
    assert sent[2]["error"].startswith("a frame of 3 values; the map takes")
    assert sent[4]["error"].startswith("value 0 of the frame is nan")
    assert (stats.received, stats.answered, stats.errors, stats.dropped) == (6, 6, 3, 0)
    assert stats.late == 6  # every answer came long after its arrival time, 0 s
    batches = iter([[(0.0, lines[0])], [(0.0, line) for line in lines[1:5]], [(0.0, lines[5])]])
    sent = []
    stats = serve(
        rec, FrameDecoder(layout, to_pa), lambda: next(batches, None), sent.append, latest=True
    )
    assert [a["frame"] for a in sent] == [0, 4, 5] and stats.dropped == 3


def hostile_frames(n: int) -> dict[bytes, str]:
    """Lines a robot's bug (or an attacker) may send to a map of ``n`` taxels, each with words
    its error line holds: none may end the stream, and raw counts outside what a 16-bit skin
    reads are refused, as handskin ingest refuses them."""
    zeros = ",".join(["0"] * (n - 1))
    row = lambda v: ",".join([v] * n).encode()  # noqa: E731
    return {
        f"[{'1' * 400},{zeros}]".encode(): "value 0 of the frame is inf",  # was OverflowError
        f"{'1' * 400},{zeros}".encode(): "value 0 of the frame is inf",
        b"[" * 2000 + b"]" * 2000: "JSON arrays nested 2000 deep",  # was RecursionError
        json.dumps([[0] * (n // 2), [0] * (n - n // 2)]).encode(): "nested 2 deep",
        b'{"frame": [0, 0]}': "not a frame: a JSON object",
        json.dumps(["0"] * n).encode(): "JSON str values",
        json.dumps([True] * n).encode(): "JSON bool values",
        b"1," * 3_000_000 + b"1": f"a line of more than {32 * n + 64} bytes",
        b"\xff\xfe\x00" * 50: "byte 0xff at offset 0 is not UTF-8",
        row("-5"): "value 0 is -5, outside 0..65535",
        row("70000"): "value 0 is 70000, outside 0..65535",
        row("1e300"): "value 0 is 1e+300, outside 0..65535",
        row("12.5"): "value 0 is 12.5, not an integer count",
        b"[]": "a frame of 0 values",
    }


def test_no_frame_ends_the_stream(frames, predictors):
    """Each hostile line gets its error line and the good frame after it its answer."""
    tmap, layout, to_pa, raw = frames
    rec = Recognizer(tmap, *predictors)
    bad = hostile_frames(tmap.n_taxels)
    good = ",".join(map(str, raw[0].astype(np.int64))).encode()
    lines = [x for line in bad for x in (line, good)]
    batches = iter([[(0.0, line)] for line in lines])
    sent: list[dict] = []
    stats = serve(rec, FrameDecoder(layout, to_pa), lambda: next(batches, None), sent.append)
    assert [a["frame"] for a in sent] == list(range(len(lines)))
    for answer, words in zip(sent[::2], bad.values(), strict=True):
        assert words in answer["error"], (words, answer)
    for answer in sent[1::2]:
        check_answer(answer, predict_frame(to_pa(raw[0]), tmap, *predictors))
    assert (stats.received, stats.errors) == (len(lines), len(bad))


def test_a_line_longer_than_any_frame_is_cut_and_the_next_read():
    from learn.infer.transport import lines

    data = io.BytesIO(b"1,2\n" + b"9" * 10_000 + b"\n\n  \n3,4")
    assert list(lines(data, max_bytes=100)) == [b"1,2\n", b"9" * 101, b"3,4"]


def test_a_layout_map_takes_any_finite_pressure(frames, tmp_path):
    """Pa for a layout file's map: no raw-count range (negative pressures are a baseline's)."""
    _, layout, _, _ = frames
    layout.save(tmp_path / "layout.npz")
    _, layout, units = load_map(tmp_path / "layout.npz")
    p = np.full(layout.n_taxels, -12.5)
    assert np.array_equal(FrameDecoder(layout, units)(",".join(map(str, p)).encode()), p)


def recorded_sequence(raw: np.ndarray) -> list[bytes]:
    """The frames as a robot would send them: CSV lines and JSON arrays, raw counts."""
    return [
        (json.dumps(r.tolist()) if i % 3 == 0 else ",".join(map(str, r))).encode()
        for i, r in enumerate(raw.astype(np.int64))
    ]


def stream_args(checkpoints, data) -> list[str]:
    args = [sys.executable, "-c", "from handskin.cli import main; main()", "stream"]
    args += ["--map", str(data), "--classifier", str(checkpoints["handsnet"])]
    return [*args, "--segmenter", str(checkpoints["segnet"]), "--threads", "1"]


def check_stream(answers: list[dict], frames, predictors) -> None:
    tmap, _, to_pa, raw = frames
    assert [a["frame"] for a in answers] == list(range(len(raw) + 1))
    assert "a frame of 3 values" in answers[-1]["error"]
    for answer, r in zip(answers, raw, strict=False):
        check_answer(answer, predict_frame(to_pa(r), tmap, *predictors))


def test_stream_command_over_stdin(checkpoints, tiny_dataset, frames, predictors):
    lines = [*recorded_sequence(frames[3]), b"1,2,3"]
    res = subprocess.run(
        stream_args(checkpoints, tiny_dataset),
        input=b"\n".join(lines) + b"\n",
        capture_output=True,
        timeout=120,
    )
    answers = [json.loads(line) for line in res.stdout.splitlines()]
    check_stream(answers, frames, predictors)
    assert f"stream: {len(lines)} frames, {len(lines)} answered (1 errors)" in res.stderr.decode()
    assert res.returncode == 1, res.stderr.decode()  # a frame got an error: said at the end too


def test_stream_command_exit_status(checkpoints, tiny_dataset, frames):
    """0 when every frame was answered, 1 when one got an error line (after the others)."""
    good = recorded_sequence(frames[3][:3])
    for lines, status in ((good, 0), ([b"-1," * 3 + b"[[[", *good], 1)):
        res = subprocess.run(
            stream_args(checkpoints, tiny_dataset),
            input=b"\n".join(lines) + b"\n",
            capture_output=True,
            timeout=120,
        )
        assert res.returncode == status, res.stderr.decode()
        assert len(res.stdout.splitlines()) == len(lines)
        assert "Traceback" not in res.stderr.decode()


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_stream_command_over_zmq(checkpoints, tiny_dataset, frames, predictors):
    zmq = pytest.importorskip("zmq")
    inp, out = (f"tcp://127.0.0.1:{free_port()}" for _ in range(2))
    args = [*stream_args(checkpoints, tiny_dataset), "--zmq", inp, "--zmq-out", out]
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    ctx = zmq.Context()
    push, pull = ctx.socket(zmq.PUSH), ctx.socket(zmq.PULL)
    push.connect(inp)
    pull.connect(out)
    pull.setsockopt(zmq.RCVTIMEO, 120_000)
    lines = [*recorded_sequence(frames[3]), b"1,2,3"]
    sender = threading.Thread(target=lambda: [push.send(m) for m in [*lines, b""]])
    sender.start()
    try:
        answers = [json.loads(pull.recv()) for _ in lines]
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
        sender.join()
        ctx.destroy(linger=0)
    assert proc.returncode == 1, err.decode()  # the last frame got an error
    check_stream(answers, frames, predictors)


def test_stream_command_errors(checkpoints, tiny_dataset):
    from typer.testing import CliRunner

    from handskin.cli import app

    args = ["stream", "--map", str(tiny_dataset)]
    res = CliRunner().invoke(app, [*args, "--classifier", "nope.pt"])
    assert res.exit_code == 2 and "no checkpoint at nope.pt" in res.output
    res = CliRunner().invoke(app, [*args, "--segmenter", str(checkpoints["segnet"]), "--int8"])
    assert res.exit_code == 2 and "--int8 makes the classifier" in res.output
    res = CliRunner().invoke(app, [*args, "--classifier", str(checkpoints["handsnet"]), "--bf16"])
    assert res.exit_code == 2 and "--bf16 stores the segmenter's weights" in res.output
    seg = ["--segmenter", str(checkpoints["segnet"])]
    res = CliRunner().invoke(app, [*args, *seg, "--period-ms", "0"])
    assert res.exit_code == 2 and "--period-ms 0" in res.output
    res = CliRunner().invoke(app, [*args, *seg, "--zmq", "tcp://nowhere:x"])
    assert res.exit_code == 2 and "--zmq tcp://nowhere:x: cannot bind" in res.output


def test_step_runs_its_networks_flushing_subnormals(frames, predictors, monkeypatch):
    """Every convolution of a step runs with subnormal floats flushed (`learn.numerics`)."""
    tmap, _, to_pa, raw = frames
    rec = Recognizer(tmap, *predictors)
    subnormal = np.array([0x100], dtype=np.uint32).view(np.float32)
    kept: list[bool] = []
    real = torch.nn.Conv2d.forward

    def recording(self, x):
        kept.append(bool((subnormal * np.float32(1)).view(np.uint32)[0]))
        return real(self, x)

    monkeypatch.setattr(torch.nn.Conv2d, "forward", recording)
    rec.step(to_pa(raw[0]))
    assert kept and not any(kept)
    assert bool((subnormal * np.float32(1)).view(np.uint32)[0])  # IEEE again after the step
