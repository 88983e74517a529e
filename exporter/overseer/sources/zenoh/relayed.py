"""The Zenoh transport of an ingest worker: its robots' samples and every token, relayed by the exporter.

The exporter's process holds the one Zenoh session (`relay.py`) and sends each worker, down a pipe, the
samples of the robots it owns and every publisher token, in order, the samples' payloads through a ring of
memory both processes map (`shared_ring.py`). This reads them into the same ingest as a session of its own
would (`ingest.py`).
"""

from __future__ import annotations

import logging
import threading

from overseer.config.fleet import DEFAULT_NAMESPACE_DEPTH
from overseer.config.zenoh import ZenohConfig
from overseer.model import FleetModel
from overseer.model.shard import Shard
from overseer.sources.robot_naming import RobotNaming
from overseer.sources.zenoh.ingest import TICK_SECONDS, TRANSPORT, ZenohIngest
from overseer.sources.zenoh.relay_items import RelayedFeed, decode_batch

log = logging.getLogger(__name__)


class RelayedZenohSource:
    """Feeds a worker's model from what the exporter's Zenoh relay sends it down `feed`."""

    transport = TRANSPORT

    def __init__(
        self,
        config: ZenohConfig,
        model: FleetModel,
        shard: Shard,
        feed: RelayedFeed,
        namespace_depth: int = DEFAULT_NAMESPACE_DEPTH,
    ) -> None:
        """Feed `model` with the robots `shard` owns, from the batches read from `feed`."""
        naming = RobotNaming(config.unnamespaced_robot, config.robot_name is not None, namespace_depth)
        # The relay sends what every worker would see alike (a bad key, an unreachable router) to the first.
        self.ingest = ZenohIngest(config, model, shard, naming, counts_shared_errors=shard.worker == 0)
        self._feed = feed
        self.samples_heard = 0  # samples the relay sent this worker
        self._stop = threading.Event()

    def start(self) -> None:
        """Read the relay's batches, and keep the ingest's upkeep going, in background threads."""
        threading.Thread(target=self._read, name="zenoh-relayed", daemon=True).start()
        threading.Thread(target=self._upkeep, name="zenoh-upkeep", daemon=True).start()

    def stop(self) -> None:
        """Stop reading: the exporter closes the pipe when it stops or restarts the worker."""
        self._stop.set()

    def _read(self) -> None:
        ingest, connection, ring = self.ingest, self._feed.connection, self._feed.ring
        while not self._stop.is_set():
            try:
                batch = decode_batch(connection.recv_bytes(), ring)
            except (EOFError, OSError):
                return  # the exporter is gone or stopping
            self.samples_heard += ingest.on_items(batch)

    def _upkeep(self) -> None:
        while not self._stop.wait(TICK_SECONDS):
            try:
                self.ingest.tick()
            except Exception:  # a bug here must not end the upkeep for good
                log.exception("Zenoh upkeep failed")
