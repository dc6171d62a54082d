"""The loop of `handskin stream`: raw frames in, one JSON answer out per frame, with its latency.

Frames come one per line on standard input or one per message on a ZeroMQ PULL socket (pyzmq,
the ``stream`` extra): N taxel or C channel values, as comma-separated numbers or a JSON array,
raw counts for a dataset's map (converted as it converts them) or pascals for a layout file's.
An empty message ends a ZeroMQ stream; end of file ends standard input. Each answer is a JSON
object on standard output or a message on a ZeroMQ PUSH socket:

    {"frame": 7, "class": "hand", "probability": 0.98, "parts": {"thumb": {"taxels": 12,
     "mean_pa": 2301.5}, ...}, "taxel_labels": [0, 0, 3, ...], "latency_ms": 3.1}

``frame`` counts the frames received from 0; ``latency_ms`` runs from the frame's arrival to
its answer (waiting, parsing and recognition). A frame that cannot be read is answered
``{"frame": 7, "error": "..."}`` and the stream goes on: the wrong length, a value that is no
finite number (or, for a dataset's map, no raw count in 0..65535), a line longer than the map's
frames can be (`BYTES_PER_VALUE` a value), nested JSON arrays, text that is not UTF-8.
An answer later than the frame period is counted late; with ``latest``, frames that wait while
another is recognised are dropped (counted), all but the newest.
"""

from __future__ import annotations

import json
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from learn.infer import transport as T
from learn.infer.predict import FrameUnits, load_map, load_predictor
from learn.infer.stream import Recognizer, bf16_weights, compiled
from tactile.errors import ConfigError, DataError, HandskinError
from tactile.geometry.layout import TaxelLayout

BYTES_PER_VALUE = 32  # the longest a value takes in a line: "-1.2345678901234567e+300, " is 26
FRAME_ERRORS = (ValueError, TypeError, ArithmeticError, RecursionError)  # a frame's own failures


def parse_values(payload: bytes, max_bytes: int | None = None) -> np.ndarray:
    """The numbers of one line or message: one flat JSON array of numbers or comma-separated
    numbers, at most ``max_bytes`` long; DataError naming what else it is."""
    if max_bytes is not None and len(payload.rstrip(b"\r\n")) > max_bytes:
        raise DataError(
            f"a line of more than {max_bytes} bytes, longer than any frame of this map "
            f"({BYTES_PER_VALUE} bytes a value). Fix: one frame per line"
        )
    try:
        text = payload.decode("utf-8").strip()
    except UnicodeDecodeError as err:
        raise DataError(
            f"not a frame: byte 0x{payload[err.start]:02x} at offset {err.start} is not UTF-8 "
            "text. Fix: send each frame as text, one per line"
        ) from None
    values = _json_numbers(text) if text.startswith(("[", "{")) else text.split(",")
    try:
        return np.asarray(values, dtype=np.float64).reshape(-1)
    except FRAME_ERRORS as err:
        raise _not_a_frame(text, err) from None


def _json_numbers(text: str) -> list[float]:
    """The numbers of a flat JSON array (nesting 1); DataError for anything else."""
    brackets = np.frombuffer(text.encode(), np.uint8)
    depth = np.cumsum((brackets == ord("[")).astype(np.int64) - (brackets == ord("]")))
    if depth.max(initial=0) > 1:
        raise DataError(
            f"not a frame: JSON arrays nested {int(depth.max())} deep; a frame is one flat "
            "array of numbers (nesting 1). Fix: [v0, v1, ...]"
        )
    try:  # numbers as floats: a 400-digit integer is inf, refused below, not an OverflowError
        values = json.loads(text, parse_int=float, parse_constant=float)
    except FRAME_ERRORS as err:
        raise _not_a_frame(text, err) from None
    kinds = sorted({type(v).__name__ for v in values if type(v) is not float})
    if not isinstance(values, list) or kinds:
        what = "a JSON object" if isinstance(values, dict) else f"JSON {', '.join(kinds)} values"
        raise DataError(f"not a frame: {what}. Fix: a JSON array of numbers, [v0, v1, ...]")
    return values


def _not_a_frame(text: str, err: Exception) -> DataError:
    shown = text if len(text) <= 40 else text[:37] + "..."
    return DataError(
        f"not a frame: {shown!r} ({str(err)[:80]}). Fix: one frame per line, numbers "
        "separated by commas or a JSON array"
    )


@dataclass(frozen=True)
class FrameDecoder:
    """Raw values to the (N,) taxel pressures, Pa, a recognizer takes: N taxel values or C
    channel values (averaged into taxels by ``layout``), then ``to_pa`` (a dataset's map: raw
    counts, each checked as `handskin ingest` checks them)."""

    layout: TaxelLayout
    to_pa: FrameUnits

    @property
    def max_bytes(self) -> int:
        """The longest line a frame of this map may take, bytes."""
        return BYTES_PER_VALUE * max(self.layout.n_taxels, self.layout.n_channels or 0) + 64

    def __call__(self, payload: bytes) -> np.ndarray:
        values = parse_values(payload, self.max_bytes)
        n, c = self.layout.n_taxels, self.layout.n_channels
        if len(values) not in (n, c):
            widths = f"{n} taxel" + ("" if c in (None, n) else f" or {c} channel")
            raise DataError(f"a frame of {len(values)} values; the map takes {widths} values")
        bad = ~np.isfinite(values)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise DataError(f"value {i} of the frame is {values[i]}; give finite numbers")
        self.to_pa.check(values)
        taxels = values if len(values) == n else self.layout.taxels_from_channels(values)
        return self.to_pa(taxels)


@dataclass
class StreamStats:
    """What a stream did: frames received, answered, answered with an error, dropped, late
    (answered later than ``period_ms`` after arrival), each answer's latency (ms), and the
    times of the first arrival and the last answer (perf_counter seconds)."""

    period_ms: float
    received: int = 0
    answered: int = 0
    errors: int = 0
    dropped: int = 0
    late: int = 0
    latency_ms: list[float] = field(default_factory=list)
    first: float | None = None
    last: float | None = None

    def record(self, answer: dict) -> dict:
        """Count ``answer`` (as `answer_frame` made it) and return it."""
        self.received += 1
        self.answered += 1
        self.errors += "error" in answer
        self.late += answer["latency_ms"] > self.period_ms
        self.latency_ms.append(answer["latency_ms"])
        self.last = time.perf_counter()
        return answer

    def summary(self) -> str:
        """One line for the user."""
        lat = np.asarray(self.latency_ms or [np.nan])
        span = (self.last or 0.0) - (self.first or 0.0)
        fps = self.answered / span if span > 0 else float("nan")
        return (
            f"stream: {self.received} frames, {self.answered} answered ({self.errors} errors), "
            f"{self.dropped} dropped, {self.late} late (> {self.period_ms:g} ms); latency "
            f"median {np.median(lat):.2f} ms, p99 {np.percentile(lat, 99):.2f}, max "
            f"{lat.max():.2f}; {fps:.0f} frames/s"
        )


def answer_frame(
    rec: Recognizer, decode: FrameDecoder, number: int, arrival: float, payload: bytes, labels: bool
) -> dict:
    """The JSON object answering frame ``number``: the recognizer's answer or the error."""
    try:
        out = {"frame": number} | rec.step(decode(payload)).as_json(labels)
    except HandskinError as err:
        out = {"frame": number, "error": str(err)}
    except FRAME_ERRORS as err:  # one that no check foresaw: the frame's error, the stream goes on
        out = {"frame": number, "error": f"not a frame ({type(err).__name__}: {str(err)[:80]})"}
    out["latency_ms"] = round(1e3 * (time.perf_counter() - arrival), 3)
    return out


def serve(
    rec: Recognizer,
    decode: FrameDecoder,
    take: Callable[[], list[T.Frame] | None],
    send: Callable[[dict], None],
    period_ms: float = 100.0,
    latest: bool = False,
    labels: bool = True,
) -> StreamStats:
    """Answer every frame ``take()`` gives (the frames waiting, at least one; None at the end)
    with ``send(answer)``; ``latest``: of the frames waiting, only the newest. Ctrl-C ends it."""
    stats = StreamStats(period_ms)
    try:
        while (waiting := take()) is not None:
            stats.first = waiting[0][0] if stats.first is None else stats.first
            if latest:
                stats.received += len(waiting) - 1
                stats.dropped += len(waiting) - 1
                waiting = waiting[-1:]
            for arrival, payload in waiting:
                send(
                    stats.record(
                        answer_frame(rec, decode, stats.received, arrival, payload, labels)
                    )
                )
    except KeyboardInterrupt:  # the end of a stream typed at a terminal; the summary follows
        pass
    return stats


@dataclass(frozen=True)
class StreamOptions:
    """`handskin stream`'s choices: frames from ``zmq_in`` (else standard input), answers to
    ``zmq_out`` (else standard output), ``period_ms`` (late after it), ``latest`` (drop all but
    the newest waiting frame), ``labels`` (per-taxel labels in answers)."""

    zmq_in: str | None = None
    zmq_out: str | None = None
    period_ms: float = 100.0
    latest: bool = False
    labels: bool = True


def load_recognizer(
    map_path: Path,
    classifier: Path | Sequence[Path] | None,
    segmenter: Path | Sequence[Path] | None,
    int8: bool = False,
    calibration: Path | None = None,
    compile_nets: bool = False,
    bf16: bool = False,
    threshold_pa: float = 0.0,
    step_mm: float = 1.0,
    threads: int = 1,
) -> tuple[Recognizer, FrameDecoder]:
    """The recognizer and frame decoder of `handskin stream`: the map of ``map_path`` (a dataset:
    frames in raw counts; a layout file: in Pa), the networks (``int8``: the classifier in 8
    bits; ``bf16``: the segmenter's weights in bfloat16; ``compile_nets``: the networks not in
    int8 compiled), ``threshold_pa`` for the part counts;
    torch set to ``threads`` CPU threads."""
    if threads < 1:
        raise ConfigError(f"--threads {threads}: give 1 or more")
    if calibration is not None and not int8:
        raise ConfigError("--calibration sets the ranges of the int8 classifier; add --int8")
    if int8 and not classifier:
        raise ConfigError("--int8 makes the classifier (HandsNet) 8-bit; give --classifier")
    if bf16 and not segmenter:
        raise ConfigError("--bf16 stores the segmenter's weights in bfloat16; give --segmenter")
    tmap, layout, to_pa = load_map(map_path, step_mm)
    torch.set_num_threads(threads)
    clf = None if not classifier else load_predictor(classifier, int8=int8, calibration=calibration)
    seg = None if not segmenter else load_predictor(segmenter)
    seg = bf16_weights(seg) if bf16 else seg
    if compile_nets:
        clf, seg = (None if p is None else compiled(p) for p in (clf, seg))
    return Recognizer(tmap, clf, seg, threshold_pa), FrameDecoder(layout, to_pa)


def run_stream(rec: Recognizer, decode: FrameDecoder, options: StreamOptions) -> StreamStats:
    """Open the input and output (sockets bound before any frame is read), then `serve`."""
    o = options
    if not o.period_ms > 0:
        raise ConfigError(f"--period-ms {o.period_ms}: give the frame period, > 0 ms")
    out = None if o.zmq_out is None else T.zmq_socket(o.zmq_out, "PUSH", "--zmq-out")
    send = T.write_line if out is None else T.send_message(out)
    messages = T.lines(sys.stdin.buffer, decode.max_bytes)
    if o.zmq_in is not None:
        messages = T.messages(T.zmq_socket(o.zmq_in, "PULL", "--zmq"))
    try:
        source = T.FrameSource(messages)
        return serve(rec, decode, source.take, send, o.period_ms, o.latest, o.labels)
    finally:
        if out is not None:
            out.close(linger=T.LINGER_MS)  # the last answers delivered, up to LINGER_MS
