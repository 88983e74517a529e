"""Counts that several processes read and write: one 8-byte slot each, in memory they all map."""

from __future__ import annotations

import mmap
import os
import weakref

from overseer.memory_file import create_memory_file

SLOT_BYTES = 8


class SharedCounts:
    """`length` signed 64-bit counts in a memory file: one process creates it, its children map it too.

    `slots` is a memoryview on the counts (index, assign, `sum`); `start_child` passes the descriptor.
    """

    def __init__(self, descriptor: int, length: int) -> None:
        """Map `length` counts of the memory file open as `descriptor` (another process's, or `create`'s)."""
        self._descriptor = descriptor
        self._map = mmap.mmap(descriptor, max(length, 1) * SLOT_BYTES)  # a mapping of its own descriptor
        self.slots = memoryview(self._map).cast("q")[:length]
        self._close = weakref.finalize(self, os.close, descriptor)

    @classmethod
    def create(cls, length: int) -> SharedCounts:
        """`length` new counts, all zero."""
        return cls(create_memory_file("overseer-counts", max(length, 1) * SLOT_BYTES), length)

    def fileno(self) -> int:
        """The memory file's descriptor, to pass to a child."""
        return self._descriptor

    def close(self) -> None:
        """Close the memory file's descriptor (`slots` stay readable until no one holds them)."""
        self._close()

    def __len__(self) -> int:
        """How many counts."""
        return len(self.slots)
