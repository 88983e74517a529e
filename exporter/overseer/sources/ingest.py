"""From one topic's raw payloads to the fleet model: decode, apply, and skip what did not change."""

from __future__ import annotations

from collections.abc import Callable
from hashlib import blake2b

from overseer.codec import DecodeError
from overseer.messages import DiagnosticArray
from overseer.model import FleetModel


class PayloadIngest:
    """Feeds one robot's diagnostics topic into the model.

    Aggregators republish the same array every second. A payload equal to the last one applied, but
    for the bytes at `ignored` (the header's sequence number and stamp), only refreshes the robot.
    Payloads are compared by a 128-bit BLAKE2 digest: keeping each robot's last payload instead would
    cost about 90 bytes per component, a tenth of the memory budget.
    """

    def __init__(
        self,
        model: FleetModel,
        robot: str,
        transport: str,
        topic: str,
        decode: Callable[[bytes], DiagnosticArray],
        ignored: tuple[int, int],
    ) -> None:
        """Ingest `topic` of `robot` with `decode`; bytes `ignored[0]:ignored[1]` may differ in repeats."""
        self._model = model
        self._robot = robot
        self._transport = transport
        self._topic = topic
        self._decode = decode
        self._start, self._end = ignored
        self._previous = b""  # digest of the last payload applied

    def __call__(self, payload: bytes) -> None:
        """Apply one payload; DecodeError (counted as decode_error) when it is not a DiagnosticArray."""
        digest = blake2b(payload[: self._start], digest_size=16)
        digest.update(payload[self._end :])
        fingerprint = digest.digest()
        if fingerprint == self._previous and self._model.touch(self._robot, self._transport):
            return
        try:
            array = self._decode(payload)
        except DecodeError:
            self._model.count_message(self._transport, "decode_error")
            raise
        self._model.apply(self._robot, array, self._transport, self._topic)
        self._previous = fingerprint
