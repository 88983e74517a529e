"""Cyclone DDS's own warnings, read back through a pipe: the samples it dropped as undecodable.

Cyclone validates every received sample against the reader's type before the application sees it, and
drops a malformed one with a warning only: no listener, status or statistic reports it. The exporter
points Cyclone's trace output at a pipe, counts those warnings as `decode_error`, and logs them.
"""

from __future__ import annotations

import logging
import os
import threading
from collections.abc import Callable

log = logging.getLogger(__name__)


class CycloneWarnings:
    """A pipe Cyclone writes its warnings to, and the thread that reads it."""

    def __init__(self, on_dropped_sample: Callable[[str], None]) -> None:
        """Call `on_dropped_sample` with Cyclone's line for every sample it drops."""
        self._on_dropped_sample = on_dropped_sample
        read_end, self._write_end = os.pipe()
        self._reader = os.fdopen(read_end, "r", encoding="utf-8", errors="replace")
        threading.Thread(target=self._read, name="cyclone-warnings", daemon=True).start()

    def config(self) -> str:
        """A Cyclone configuration fragment sending warnings (and nothing more verbose) to the pipe."""
        return (
            '<CycloneDDS><Domain id="any"><Tracing><Verbosity>warning</Verbosity>'
            f"<OutputFile>/proc/self/fd/{self._write_end}</OutputFile></Tracing></Domain></CycloneDDS>"
        )

    def _read(self) -> None:
        for line in self._reader:
            text = line.strip()
            if is_dropped_sample(text):
                self._on_dropped_sample(text)
            elif text:
                log.info("cyclonedds: %s", text)


def is_dropped_sample(line: str) -> bool:
    """True for Cyclone's warning about a sample (or a whole RTPS message) it could not decode."""
    return ("deserialization" in line and "failed" in line) or "malformed packet" in line
