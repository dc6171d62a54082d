"""`SafeSink`: the file HDF5 writes through (h5py's fileobj driver) that never fails under it.

h5py crashes (a segmentation fault) when HDF5 cannot write or flush a file, as on a full disk.
The sink hides a failed write from the library: the first OSError is kept in ``error``, and that
write and every later one are held in memory instead, so what HDF5 reads back stays what it
wrote and the file closes cleanly; the caller then raises the error (`h5io.write_h5`) and removes
the file. Writers stop early by calling `h5io.check_written` between steps, so the memory held
stays small.
"""

from __future__ import annotations

import os


class SafeSink:
    """A binary file for HDF5's fileobj driver (seek, tell, readinto, write, truncate, flush)."""

    def __init__(self, fh) -> None:
        self.fh = fh
        self.error: OSError | None = None
        self.pos = 0
        self.held: list[tuple[int, bytes]] = []  # (offset, data) written after the failure
        self.size = os.fstat(fh.fileno()).st_size

    def seek(self, offset: int, whence: int = os.SEEK_SET) -> int:
        base = {os.SEEK_SET: 0, os.SEEK_CUR: self.pos, os.SEEK_END: self.size}[whence]
        self.pos = base + offset
        return self.pos

    def tell(self) -> int:
        return self.pos

    def write(self, data) -> int:
        data = bytes(data)
        if self.error is None:
            try:
                self.fh.seek(self.pos)
                view = memoryview(data)
                while view:
                    view = view[self.fh.write(view) :]
            except OSError as err:
                self.error = err
        if self.error is not None:
            self.held.append((self.pos, data))
        self.pos += len(data)
        self.size = max(self.size, self.pos)
        return len(data)

    def readinto(self, buf) -> int:
        view = memoryview(buf).cast("B")
        n = min(len(view), max(self.size - self.pos, 0))
        self.fh.seek(self.pos)
        got = self.fh.readinto(view[:n]) or 0
        view[got:n] = bytes(n - got)
        for offset, data in self.held:  # later writes win, as on disk
            lo, hi = max(offset, self.pos), min(offset + len(data), self.pos + n)
            if lo < hi:
                view[lo - self.pos : hi - self.pos] = data[lo - offset : hi - offset]
        self.pos += n
        return n

    def read(self, n: int = -1) -> bytes:
        buf = bytearray(max(self.size - self.pos, 0) if n < 0 else n)
        return bytes(buf[: self.readinto(buf)])

    def truncate(self, size: int | None = None) -> int:
        size = self.pos if size is None else size
        if self.error is None:
            try:
                self.fh.truncate(size)
            except OSError as err:
                self.error = err
        self.held = [(o, d[: max(size - o, 0)]) for o, d in self.held if o < size]
        self.size = size
        return size

    def flush(self) -> None:
        if self.error is None:
            try:
                self.fh.flush()
            except OSError as err:
                self.error = err
