"""From one topic's raw payloads to the fleet model: decode, apply, and skip what did not change."""

from __future__ import annotations

import secrets
import threading
from array import array
from itertools import pairwise
from typing import NamedTuple

import xxhash

from overseer.codec import DecodeError, compiled
from overseer.codec.wire import StatusReader, WireFormat, decode_laid_out
from overseer.ingest.scan import scan_compiled, scan_python
from overseer.model import FleetModel

_FINGERPRINT_SEED = secrets.randbits(64)  # per process, as Python's hash is


def _fingerprint(payload: bytes, start: int) -> int:
    """A 64-bit hash of `payload` from `start` on: XXH3, seeded, without copying the bytes.

    Every message is hashed whole to tell a republished array at once (5 kB at 50 components): XXH3
    reads it in 0.3 µs where Python's SipHash of a copy took 1.9.
    """
    return xxhash.xxh3_64_intdigest(memoryview(payload)[start:], _FINGERPRINT_SEED)


class _Layout(NamedTuple):
    """Where the statuses of the last payload applied lay, and a hash of each."""

    revision: int  # the feed's revision that payload made
    fingerprint: int  # `_fingerprint` of the bytes after the stamp
    prefix: bytes  # the bytes before the stamp (the encapsulation header)
    head_hash: int  # hash of the bytes between the stamp and the first status
    bounds: array[int]  # where each status began, then where the last one ended
    hashes: array[int]  # hash of each status's bytes
    read_status: StatusReader


class PayloadIngest:
    """Feeds one feed of a robot (a diagnostics topic, or one publisher of it) into the model.

    Aggregators republish the same array every second: a payload equal to the last one applied but for
    its stamp (the same bytes before it, the same hash of those after it) only refreshes the robot.
    Most other arrays differ from the last one in a few statuses (a voltage, a temperature): a status
    whose bytes hash as they did, at an offset that keeps the format's alignment, decodes as it did, so
    only the others are decoded and applied. Hashes, not the payload, are kept: the payload would cost
    about 90 bytes a component, a tenth of the memory budget. The statuses' hashes are Python's keyed
    64-bit SipHash and the whole payload's a seeded XXH3 (both seeded per process). XXH3 is no keyed
    function: a robot could in principle craft an array taken for its last one, which hides only what
    that robot itself reports, as its own false statuses could.
    With the compiled decoder, the comparison and the decoding of what changed run in C
    (`scan.scan_compiled`, the same hashes); `scan.scan_python` is the pure-Python reference.
    """

    def __init__(
        self,
        model: FleetModel,
        robot: str,
        transport: str,
        topic: str,
        wire: WireFormat,
        feed: str | None = None,
    ) -> None:
        """Ingest `topic` of `robot` (as feed `feed`, default the topic), serialized as `wire` says."""
        self._model = model
        self._robot = robot
        self._transport = transport
        self._topic = topic
        self._feed = topic if feed is None else feed
        self._wire = wire
        self._layout: _Layout | None = None
        self._lock = threading.Lock()  # DDS may call a reader's listener from more than one thread

    def __call__(self, payload: bytes) -> None:
        """Apply one payload; DecodeError (counted as decode_error) when it is not a DiagnosticArray."""
        start, stop = self._wire.stamp
        fingerprint = _fingerprint(payload, stop)
        with self._lock:
            layout, self._layout = self._layout, None
            try:
                if layout is not None:
                    if (
                        fingerprint == layout.fingerprint
                        and payload[:start] == layout.prefix
                        and self._model.touch(self._robot, self._transport, self._feed, layout.revision)
                    ):
                        self._layout = layout
                        return
                    self._layout = self._apply_changes(payload, fingerprint, layout)
                if self._layout is None:
                    self._layout = self._apply_whole(payload, fingerprint)
            except DecodeError:
                self._model.count_message(self._transport, "decode_error")
                raise

    def _apply_whole(self, payload: bytes, fingerprint: int) -> _Layout | None:
        wire = self._wire
        laid_out = decode_laid_out(wire, payload)
        applied = self._model.apply_array(
            self._robot, laid_out.decoded, self._transport, self._topic, self._feed
        )
        if applied.revision is None:
            return None
        bounds = laid_out.bounds
        start, stop = wire.stamp
        return _Layout(
            applied.revision,
            fingerprint,
            payload[:start],
            hash(payload[stop : bounds[0]]),
            bounds,
            array("q", [hash(payload[a:b]) for a, b in pairwise(bounds)]),
            laid_out.read_status,
        )

    def _apply_changes(self, payload: bytes, fingerprint: int, layout: _Layout) -> _Layout | None:
        """Decode and apply only the statuses that changed; None when the payload must go whole."""
        wire = self._wire
        start, stop = wire.stamp
        bounds, hashes = layout.bounds, layout.hashes
        pos = bounds[0]
        end = len(payload)
        if end < pos or payload[:start] != layout.prefix or hash(payload[stop:pos]) != layout.head_hash:
            return None  # another header or status count
        misaligned = wire.alignment - 1
        # The bounds and hashes are updated in place: a failure below drops the layout.
        compiled_layout = compiled.LAYOUTS.get(layout.read_status)
        if compiled_layout is not None:
            limits = self._model.limits
            changed, pos, fits = scan_compiled(
                compiled_layout,
                payload,
                pos,
                end,
                bounds,
                hashes,
                misaligned,
                limits.max_string_length,
                limits.max_values_per_component,
            )
        else:
            changed, pos = scan_python(layout.read_status, payload, pos, end, bounds, hashes, misaligned)
            fits = False  # the model checks
        if pos > end or (wire.exact_end and pos != end):
            return None
        model = self._model
        if changed:
            revision = model.apply_changes(
                self._robot, layout.revision, changed, self._transport, self._feed, fits_limits=fits
            )
        elif model.touch(self._robot, self._transport, self._feed, layout.revision):
            revision = layout.revision  # only bytes no status holds changed (CDR padding)
        else:
            revision = None
        if revision is None:
            return None
        return layout._replace(revision=revision, fingerprint=fingerprint)
