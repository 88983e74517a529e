"""A change's time to the exporter's model, and so to `/metrics`, which is rendered from it at each scrape.

One more robot, published as rmw_zenoh publishes (`ZenohWire`), with the fleet's 50 components; every
period one of its values changes to the wall time it is sent at, written in place. Once a change is
sent, a thread reads that robot's JSON document from the exporter every `poll` seconds until it shows
it; the first read that does gives that change's latency: an upper bound, by at most one poll and one
read. Between a change seen and the next one sent it does not read: a 50-component document costs the
exporter about a millisecond to build, and 20 reads a second were 3-4 % of a core at 3,000 robots with
two ingest workers (whose answers cross a pipe), counted in its CPU a message. A change that takes
longer to show is read for longer: about 1 + latency / poll reads a change.
"""

from __future__ import annotations

import json
import statistics
import struct
import threading
import time
import urllib.request
from types import TracebackType

from bench.common import Row
from bench.loadgen_payloads import leaf_count, value_offset
from bench.loadgen_wire import ZenohEndpoints, ZenohWire
from overseer.codec.cdr import WIRE_FORMAT, encode_diagnostic_array
from overseer.codec.wire import decode_laid_out
from overseer.messages import DiagnosticArray
from overseer.simulator.design import aggregated_statuses, initial_levels, leaf_components

PROBE_ROBOT = "probe"
TARGET_SECONDS = 1.0  # a change's time to /metrics, p99
SETTLED = 10  # changes in a row within the target: the first look is over
SENT_KEY = "sent"
SENT_WIDTH = 17  # a wall time as 0000000000.000000
_STAMP = struct.Struct("<iI")


def probe_payload(components: int) -> tuple[bytearray, int]:
    """The probe's array of `components` statuses, encoded, and where the sent time's text starts."""
    leaves = leaf_components(leaf_count(components))
    statuses = aggregated_statuses(leaves, initial_levels(leaves, 0, 0), set())
    first = next(index for index, status in enumerate(statuses) if status.values)
    statuses[first] = statuses[first]._replace(values=((SENT_KEY, "0" * SENT_WIDTH),))
    encoded = encode_diagnostic_array(DiagnosticArray(0, 0, "", tuple(statuses)))
    payload = bytearray(encoded + b"\x00" * (-len(encoded) & 3))
    bounds = decode_laid_out(WIRE_FORMAT, bytes(payload)).bounds
    return payload, value_offset(bytes(payload), bounds[first], bounds[first + 1], SENT_KEY, "0" * SENT_WIDTH)


def percentile(ordered: list[float], share: float) -> float:
    """The value `share` of the way up `ordered` (sorted, not empty)."""
    return ordered[min(len(ordered) - 1, int(share * len(ordered)))]


def sent_time(document: dict[str, object]) -> float | None:
    """The sent time the probe's robot document shows, if any."""
    for component in document.get("components", []):  # type: ignore[attr-defined]
        for value in component.get("values", []):
            if value["key"] == SENT_KEY:
                return float(value["value"])
    return None


class ChangeProbe:
    """The probe robot and its reader, for a `with` block: `latencies` are what it measured."""

    def __init__(
        self,
        exporter_url: str,
        zenoh_endpoint: str,
        components: int = 50,
        period: float = 1.0,
        poll: float = 0.05,
    ) -> None:
        """Connect a Zenoh peer to `zenoh_endpoint`; nothing is published before the block starts."""
        self._url = f"{exporter_url}/api/v1/robots/{PROBE_ROBOT}"
        self._wire = ZenohWire([PROBE_ROBOT], 0, ZenohEndpoints(connect=(zenoh_endpoint,)))
        self._payload, self._offset = probe_payload(components)
        self._period, self._poll = period, poll
        self._stop = threading.Event()
        self._threads = [threading.Thread(target=self._publish), threading.Thread(target=self._read)]
        self.latencies: list[float] = []  # seconds from sending a change to reading it
        self.sent_at: list[float] = []  # when each of them was sent (wall clock)
        self.started_at = 0.0  # when the probe began to publish (wall clock)
        self.failed_reads = 0
        self.reads = 0
        self.published = 0
        self._sent = threading.Condition()
        self._latest: float | None = None  # the sent time of the last change published

    def __enter__(self) -> ChangeProbe:
        self.started_at = time.time()
        self._wire.open(0)
        for thread in self._threads:
            thread.start()
        return self

    def __exit__(
        self, kind: type[BaseException] | None, error: BaseException | None, trace: TracebackType | None
    ) -> None:
        self._stop.set()
        with self._sent:
            self._sent.notify_all()
        for thread in self._threads:
            thread.join()
        self._wire.shut()

    def first_look_seconds(self) -> float:
        """From the probe's start to the first of `SETTLED` changes in a row within `TARGET_SECONDS`.

        While the exporter first hears a fleet (every robot's first array read whole, one event a
        component), what arrives waits behind it, and the backlog peaks seconds after the fleet's first
        publications: its end is when changes keep arriving in time.
        """
        in_time = [latency <= TARGET_SECONDS for latency in self.latencies]
        for index in range(len(in_time) - SETTLED + 1):
            if all(in_time[index : index + SETTLED]):
                return self.sent_at[index] - self.started_at
        return float("nan")

    def rows(self, label: str) -> list[Row]:
        """Median, p99 and worst of the latencies, over the window and after the first look (held to 1 s)."""
        ordered = sorted(self.latencies) or [float("nan")]
        first_look = self.first_look_seconds()
        steady = sorted(
            latency
            for sent, latency in zip(self.sent_at, self.latencies, strict=True)
            if sent - self.started_at >= first_look
        )
        p99, steady_p99 = percentile(ordered, 0.99), percentile(steady or [float("nan")], 0.99)
        return [
            Row("scale", f"{label}: a change to /metrics, median", statistics.median(ordered), "s"),
            Row("scale", f"{label}: a change to /metrics, p99 (the whole window)", p99, "s"),
            Row("scale", f"{label}: a change to /metrics, worst", ordered[-1], "s"),
            Row("scale", f"{label}: the first look (until changes take under 1 s)", first_look, "s"),
            Row(
                "scale",
                f"{label}: a change to /metrics after the first look, p99 (of {len(steady)})",
                steady_p99,
                "s",
                f"<= {TARGET_SECONDS:g}",
                steady_p99 <= TARGET_SECONDS,
            ),
            Row(
                "scale", f"{label}: changes timed", len(self.latencies), f"({self.failed_reads} failed reads)"
            ),
        ]

    def _publish(self) -> None:
        while not self._stop.is_set():
            now = time.time()
            text = f"{now:0{SENT_WIDTH}.6f}".encode()
            self._payload[self._offset : self._offset + SENT_WIDTH] = text
            stamp = _STAMP.pack(*divmod(time.time_ns(), 1_000_000_000))
            self.published += self._wire.publish(0, 1, [self._payload], stamp)
            with self._sent:
                self._latest = float(text)
                self._sent.notify_all()
            self._stop.wait(self._period)

    def _await_change(self, seen: float | None) -> bool:
        """Wait until a change newer than `seen` was sent (True), or the probe stops (False)."""
        with self._sent:
            while seen is not None and self._latest == seen and not self._stop.is_set():
                self._sent.wait()
            return not self._stop.is_set()

    def _read(self) -> None:
        last: float | None = None
        # Waits for a change before the poll: a read at once after the change is sent would show the old one.
        while self._await_change(last) and not self._stop.wait(self._poll):
            self.reads += 1
            try:
                with urllib.request.urlopen(self._url, timeout=10) as response:
                    sent = sent_time(json.load(response))
            except (OSError, ValueError):
                self.failed_reads += 1  # 404 until the probe is first heard; a timeout under load
                continue
            seen = time.time()
            if sent is not None and sent != last:
                if last is not None:  # the first one may have arrived long before the first read
                    self.latencies.append(seen - sent)
                    self.sent_at.append(sent)
                last = sent
