"""The payloads the exporter's Zenoh relay hands one worker, in memory both processes map: no pipe copies.

Through a pipe, a 4 kB payload is copied into the pickle, into the kernel, out of it and out of the
pickle again: 6.5-11.5 µs a sample of the two processes' CPU, measured beside 2.0-2.3 µs when the relay
copies it into a ring of memory the worker maps and the pipe carries only the batch's keys and lengths
(bench/README.md, 2026-12-02, midday). The relay writes each batch's payloads one after another into the ring
and the worker, once it has copied them out, tells how far it has read in the ring's header; what it has
not read yet is never overwritten. A batch that does not fit goes down the pipe whole, as before.

Positions count bytes written since the ring was made and never wrap; a batch starts at the ring's
beginning again rather than wrap around its end. The payloads reach the worker before the pipe's message
that names them, and the pipe's system calls order the two. The header's position is written by the
worker only, after it has copied the payloads out, and read by the relay only: an older value there only
makes the ring seem fuller than it is. That the relay never sees the position before the worker's
copies are done, nor half written, holds where a store stays behind the loads before it and an aligned
8-byte store is one (x86-64); elsewhere no ring is used (`SUPPORTED`) and the payloads take the pipe.
"""

from __future__ import annotations

import mmap
import os
import platform
import struct
import weakref
from collections.abc import Sequence

from overseer.memory_file import create_memory_file

HEADER_BYTES = 64  # the reader's position first; the rest keeps the payloads off the header's cache line
# A worker's batch gathers for 50 ms: at 10,000 robots of 4 kB at 1 Hz shared by two workers, 1 MB. The
# ring holds four; larger batches (a first look's backlog) take the pipe. Both processes map it whole.
DEFAULT_RING_BYTES = 4 << 20
_POSITION = struct.Struct("<Q")
SUPPORTED = platform.machine().lower() in ("x86_64", "amd64")  # see above
_POPULATE = getattr(mmap, "MAP_POPULATE", 0)  # Linux


class SharedRing:
    """`size` bytes of payloads in a memory file: the relay places batches, the worker takes them."""

    def __init__(self, descriptor: int, size: int) -> None:
        """Map the ring of `size` bytes in the memory file open as `descriptor` (made by `create`)."""
        self._descriptor = descriptor
        self.size = size
        # Mapped whole at once (MAP_POPULATE): the ring is resident from the start, rather than growing
        # page by page as the positions first go round it (which looked like a leak for a minute).
        self._map = mmap.mmap(descriptor, HEADER_BYTES + size, flags=mmap.MAP_SHARED | _POPULATE)
        self._written = 0  # the writer's own position
        self._close = weakref.finalize(self, os.close, descriptor)

    @classmethod
    def create(cls, size: int = DEFAULT_RING_BYTES) -> SharedRing:
        """A new, empty ring of `size` bytes."""
        descriptor = create_memory_file("overseer-relay", HEADER_BYTES + size)
        try:
            return cls(descriptor, size)
        except BaseException:
            os.close(descriptor)
            raise

    def fileno(self) -> int:
        """The memory file's descriptor, to pass to the worker."""
        return self._descriptor

    def close(self) -> None:
        """Close the memory file's descriptor; the mapping stays until no one holds the ring."""
        self._close()

    def place(self, payloads: Sequence[bytes]) -> tuple[int, int] | None:
        """Copy `payloads` into the ring one after another: their start and end; None if they do not fit."""
        needed = sum(len(payload) for payload in payloads)
        start = self._written
        if start % self.size + needed > self.size:
            start += self.size - start % self.size  # the batch begins the ring again rather than wrap
        if start + needed - self._read_position() > self.size:
            return None
        offset = HEADER_BYTES + start % self.size
        ring = self._map
        for payload in payloads:
            end = offset + len(payload)
            ring[offset:end] = payload
            offset = end
        self._written = start + needed
        return start, self._written

    def take(self, start: int, lengths: Sequence[int]) -> list[bytes]:
        """Copies of the payloads of `lengths` bytes each placed from `start` on."""
        offset = HEADER_BYTES + start % self.size
        ring = self._map
        taken = []
        for length in lengths:
            end = offset + length
            taken.append(ring[offset:end])
            offset = end
        return taken

    def release(self, end: int) -> None:
        """Let the relay write over everything placed before `end`: the worker has taken it."""
        _POSITION.pack_into(self._map, 0, end)

    def _read_position(self) -> int:
        position: int = _POSITION.unpack_from(self._map, 0)[0]
        return position
