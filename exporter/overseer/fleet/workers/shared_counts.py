"""Counts that several processes read and write: one 8-byte slot each, in memory they all map."""

from __future__ import annotations

import mmap
import os

SLOT_BYTES = 8


class SharedCounts:
    """`len` signed 64-bit counts in a memory file: the parent creates it, a child attaches by descriptor.

    `slots` is a memoryview on the counts (index, assign, `sum`); `start_child` passes the descriptor.
    """

    def __init__(self, descriptor: int, length: int) -> None:
        """Map `length` counts of the memory file open as `descriptor` (another process's, or `create`'s)."""
        self._descriptor = descriptor
        self._map = mmap.mmap(descriptor, max(length, 1) * SLOT_BYTES)
        self.slots = memoryview(self._map).cast("q")[:length]

    @classmethod
    def create(cls, length: int) -> SharedCounts:
        """`length` new counts, all zero."""
        descriptor = os.memfd_create("overseer-counts", os.MFD_CLOEXEC)
        os.ftruncate(descriptor, max(length, 1) * SLOT_BYTES)
        return cls(descriptor, length)

    def fileno(self) -> int:
        """The memory file's descriptor, to pass to a child."""
        return self._descriptor

    def __len__(self) -> int:
        """How many counts."""
        return len(self.slots)
