"""How `handskin stream`'s frames come and its answers go: standard input's lines or a ZeroMQ
PULL socket's messages in, read by a thread that stamps each with its arrival time; JSON lines
on standard output or JSON messages on a ZeroMQ PUSH socket out (pyzmq: the ``stream`` extra).
"""

from __future__ import annotations

import json
import sys
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator

from tactile.errors import ConfigError

Frame = tuple[float, bytes]  # (arrival time, perf_counter seconds; the line or message)
LINGER_MS = 1000  # how long a closing ZeroMQ socket still delivers its messages, ms


class FrameSource:
    """Frames read by a thread as they come (``messages``: lines or messages, an iterable of
    bytes), each with its arrival time; ``take()`` waits for frames and returns those waiting,
    oldest first (None once the messages have ended)."""

    def __init__(self, messages: Iterable[bytes]) -> None:
        self._frames: deque[Frame] = deque()
        self._ready = threading.Condition()
        self._ended = False
        threading.Thread(target=self._read, args=(messages,), daemon=True).start()

    def _read(self, messages: Iterable[bytes]) -> None:
        try:
            for message in messages:
                with self._ready:
                    self._frames.append((time.perf_counter(), message))
                    self._ready.notify()
        finally:
            with self._ready:
                self._ended = True
                self._ready.notify()

    def take(self) -> list[Frame] | None:
        with self._ready:
            self._ready.wait_for(lambda: self._frames or self._ended)
            if not self._frames:
                return None
            waiting = list(self._frames)
            self._frames.clear()
            return waiting


def lines(stream, max_bytes: int | None = None) -> Iterator[bytes]:
    """The non-blank lines of a binary stream (standard input's ``sys.stdin.buffer``); a line
    longer than ``max_bytes`` comes as its first ``max_bytes + 1`` bytes, the rest read past,
    so that no line fills the memory."""
    limit = -1 if max_bytes is None else max_bytes + 1
    while line := stream.readline(limit):
        if len(line) == limit and not line.endswith(b"\n"):  # cut: skip to the line's end
            while (rest := stream.readline(limit)) and not rest.endswith(b"\n"):
                pass
        if line.strip():
            yield line


def zmq_socket(address: str, kind: str, option: str):
    """A ZeroMQ socket of ``kind`` ("PULL", "PUSH") bound at ``address`` (``option``: the
    flag that named it, for the error)."""
    try:
        import zmq  # optional: pyzmq
    except ImportError as err:
        raise ConfigError(
            f"{option} needs pyzmq. Fix: pip install 'handskin[stream]' (or pyzmq)"
        ) from err
    sock = zmq.Context.instance().socket(getattr(zmq, kind))
    sock.setsockopt(zmq.LINGER, LINGER_MS)
    try:
        sock.bind(address)
    except zmq.ZMQError as err:
        sock.close()
        raise ConfigError(
            f"{option} {address}: cannot bind ({err}). Fix: a free local address, e.g. "
            "tcp://127.0.0.1:5555 or ipc:///tmp/skin"
        ) from err
    return sock


def messages(sock) -> Iterator[bytes]:
    """The messages of a ZeroMQ PULL socket until an empty one."""
    while message := sock.recv():
        yield message


def write_line(answer: dict, out=None) -> None:
    """``answer`` as one JSON line on ``out`` (standard output), flushed."""
    out = sys.stdout if out is None else out
    out.write(json.dumps(answer, separators=(",", ":")) + "\n")
    out.flush()


def send_message(sock) -> Callable[[dict], None]:
    """``send(answer)``: each answer as a JSON message on a ZeroMQ PUSH socket."""
    return lambda answer: sock.send(json.dumps(answer, separators=(",", ":")).encode())
