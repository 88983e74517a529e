"""The DDS transport of an ingest worker: its robots' samples and the source's calls, relayed by the exporter.

The exporter's process holds the one DDS source (`relay.py`) and sends each worker, down a pipe, the
serialized samples of the robots it owns, each with its robot, topic and feed, and the source's calls of
the model for those robots, in order, the payloads through a ring of memory both processes map. This
decodes the samples into the worker's model, one ingest per writer, as the source of one process does.
"""

from __future__ import annotations

import logging
import threading
from typing import Any

from overseer.model import FleetModel
from overseer.sources.dds.sink import TRANSPORT, Ingest, ModelSink, take_sample
from overseer.sources.zenoh.relay_items import CALL, DROPPED, SAMPLE, Item, RelayedFeed, decode_batch

log = logging.getLogger(__name__)

# The model's calls the exporter's DDS source may make (`sink.DdsSink`); the relay adds its own two.
_CALLS = frozenset(
    {"count_message", "count_source_error", "register", "forget_topic", "forget_feed", "publisher_left"}
)

_FeedKey = tuple[str, str, str]  # (robot, topic, feed)
# Writers let go of, remembered so that a sample the source took just before is not taken for a new
# writer, until the source follows the writer again (one whose lease ran out, back with its GUID).
MAX_RELEASED = 100_000


class RelayedDdsSource:
    """Feeds a worker's model from what the exporter's DDS relay sends it down `feed`."""

    transport = TRANSPORT

    def __init__(self, model: FleetModel, feed: RelayedFeed) -> None:
        """Feed `model` from the batches read from `feed`."""
        self._sink = ModelSink(model)
        self._feed = feed
        self._ingests: dict[_FeedKey, Ingest] = {}
        self._released: dict[_FeedKey, None] = {}  # in the order they were let go of
        self._refused: set[str] = set()  # robots the model's cap refused: their samples are not taken
        self.samples_heard = 0  # samples the relay sent this worker
        self._stop = threading.Event()

    def start(self) -> None:
        """Read the relay's batches in a background thread."""
        threading.Thread(target=self._read, name="dds-relayed", daemon=True).start()

    def stop(self) -> None:
        """Stop reading: the exporter closes the pipe when it stops or restarts the worker."""
        self._stop.set()

    def on_items(self, items: list[Item]) -> None:
        """Take one batch: decode each sample into the model, make each call."""
        for item in items:
            kind = item[0]
            try:
                if kind == SAMPLE:
                    self.samples_heard += 1
                    self._take(item[1], item[3])
                elif kind == CALL:
                    self._call(item[1], item[2])
                elif kind == DROPPED:
                    self._sink.count_message(TRANSPORT, "dropped", item[1])
            except Exception:  # a bug with one item must not lose the rest of the batch
                log.exception("failed to take a relayed DDS item of kind %s", kind)

    def _take(self, key: _FeedKey, payload: bytes) -> None:
        ingest = self._ingests.get(key)
        if ingest is None:
            robot, topic, feed = key
            if robot in self._refused or key in self._released:
                return
            ingest = self._ingests[key] = self._sink.ingest(robot, topic, feed)
        take_sample(ingest, payload, key[1])

    def _call(self, method: str, arguments: tuple[Any, ...]) -> None:
        if method == "followed":
            self._released.pop(arguments, None)
            return
        if method == "released":
            self._ingests.pop(arguments, None)
            self._released[arguments] = None
            if len(self._released) > MAX_RELEASED:
                del self._released[next(iter(self._released))]
            return
        if method not in _CALLS:
            log.error("the DDS relay asked for %r, which is no call of the model", method)
            return
        result = getattr(self._sink, method)(*arguments)
        if method == "register":
            robot = arguments[0]
            if result:
                self._refused.discard(robot)
            elif robot not in self._refused:
                self._refused.add(robot)
                log.warning("robot cap reached; not following robot %s", robot)
        elif method == "publisher_left":
            self._refused.discard(arguments[0])  # a writer of its own again registers it anew
        elif method == "forget_feed":
            robot, feed = arguments[0], arguments[1]
            for key in [key for key in self._ingests if key[0] == robot and key[2] == feed]:
                del self._ingests[key]

    def _read(self) -> None:
        connection, ring = self._feed.connection, self._feed.ring
        while not self._stop.is_set():
            try:
                data = connection.recv_bytes()
            except (EOFError, OSError):
                return  # the exporter is gone or stopping
            try:
                batch = decode_batch(data, ring)
            except Exception:  # a bug: said, and the worker goes on with the next batch
                log.exception("could not read a batch of relayed DDS samples")
                continue
            self.on_items(batch)
