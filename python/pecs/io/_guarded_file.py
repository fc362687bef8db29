"""A file object for HDF5 output that never lets a failed write reach the HDF5 library.

HDF5 (2.0, through h5py's sec2 or fileobj driver) segfaults in `H5Fclose` after a write failed
with ENOSPC: its metadata cache is left in a state the close cannot flush. So h5py writes through
this object: the first OSError is kept, later writes go to an in-memory overlay (reads see them,
so HDF5's state stays consistent), HDF5 closes normally, and the writer raises the kept error
(`raise_if_failed`) after each batch and after the close. The partial file is then deleted by
`atomic_path`.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any


class GuardedFile:
    """Read/write/seek/tell/truncate/flush over a real file, for h5py's `fileobj` driver."""

    def __init__(self, path: Path) -> None:
        self._file = open(path, "w+b", buffering=0)  # noqa: SIM115 (closed in close())
        self._position = 0
        self._size = 0
        self._overlay: list[tuple[int, bytes]] = []
        self.error: OSError | None = None

    def seek(self, offset: int, whence: int = os.SEEK_SET) -> int:
        if whence == os.SEEK_SET:
            self._position = offset
        elif whence == os.SEEK_CUR:
            self._position += offset
        else:
            self._position = self._size + offset
        return self._position

    def tell(self) -> int:
        return self._position

    def write(self, data: Any) -> int:
        view = memoryview(data).cast("B")
        if self.error is None:
            self._write_through(view)
        if self.error is not None:
            self._overlay.append((self._position, bytes(view)))
        self._position += len(view)
        self._size = max(self._size, self._position)
        return len(view)

    def _write_through(self, view: memoryview) -> None:
        try:
            self._file.seek(self._position)
            written = 0
            while written < len(view):
                # A raw write may be short when the disk fills; the next one raises ENOSPC.
                count = self._file.write(view[written:])
                if not count:
                    raise OSError(28, os.strerror(28))
                written += count
        except OSError as error:
            self.error = error

    def read(self, size: int = -1) -> bytes:
        size = max(0, self._size - self._position) if size < 0 else size
        buffer = bytearray(size)
        return bytes(buffer[: self.readinto(buffer)])

    def readinto(self, buffer: Any) -> int:
        view = memoryview(buffer).cast("B")
        self._file.seek(self._position)
        count = self._file.readinto(view) or 0
        end = min(self._position + len(view), self._size)
        wanted = max(0, end - self._position)
        if count < wanted:
            view[count:wanted] = bytes(wanted - count)
        for start, data in self._overlay:
            self._copy_overlap(view, start, data)
        self._position += wanted
        return wanted

    def _copy_overlap(self, view: memoryview, start: int, data: bytes) -> None:
        low = max(start, self._position)
        high = min(start + len(data), self._position + len(view))
        if low < high:
            view[low - self._position : high - self._position] = data[low - start : high - start]

    def truncate(self, size: int | None = None) -> int:
        size = self._position if size is None else size
        if self.error is None:
            try:
                self._file.truncate(size)
            except OSError as error:
                self.error = error
        self._size = size
        return size

    def flush(self) -> None:
        return None

    def close(self) -> None:
        try:
            self._file.close()
        except OSError as error:
            self.error = self.error or error

    def raise_if_failed(self) -> None:
        if self.error is not None:
            raise self.error
