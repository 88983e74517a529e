"""The Zenoh transport in one process: robots on rmw_zenoh (ROS 2 Jazzy) and behind zenoh-bridge-ros2dds.

The exporter's session (`receiver.py`) hands every sample and token, through a bounded queue (`outbox.py`:
Zenoh's own channel stays short while the ingest is behind), to the ingest (`ingest.py`). Payloads
are DDS CDR and go through the same ingest as DDS samples. rmw_zenoh's liveliness tokens tell when a
robot's diagnostics publisher goes (process killed, link lost), and so do zenoh-bridge-ros2dds's tokens
for the routes it serves: the robot is down at once, not after `robot_timeout`.

This is the transport of an exporter that ingests in its own process (`--ingest.workers 1`), also as one
shard of several (it hears every robot, and keeps its own by key). With several ingest workers, the
exporter's one session relays each worker its robots' samples instead (`relay.py`, `relayed.py`).
"""

from __future__ import annotations

from overseer.config.fleet import DEFAULT_NAMESPACE_DEPTH
from overseer.config.zenoh import ZenohConfig
from overseer.model import FleetModel
from overseer.model.shard import Shard
from overseer.sources.robot_naming import RobotNaming
from overseer.sources.zenoh.ingest import TRANSPORT, ZenohIngest
from overseer.sources.zenoh.outbox import Outbox
from overseer.sources.zenoh.receiver import ZenohReceiver
from overseer.sources.zenoh.relay_items import SAMPLE, TOKEN, Item


class ZenohSource:
    """Subscribes to every robot's diagnostics and publisher liveliness on one Zenoh session."""

    transport = TRANSPORT

    def __init__(
        self,
        config: ZenohConfig,
        model: FleetModel,
        shard: Shard | None = None,
        namespace_depth: int = DEFAULT_NAMESPACE_DEPTH,
    ) -> None:
        """Feed `model` from the Zenoh network in `config`; ConfigError at once if it is unusable."""
        naming = RobotNaming(config.unnamespaced_robot, config.robot_name is not None, namespace_depth)
        self.ingest = ZenohIngest(config, model, shard or Shard(), naming)
        self._outbox = Outbox(config.queue_length, self._ingest, "zenoh-ingest")
        self.receiver = ZenohReceiver(
            config,
            self._on_sample,
            self._on_token,
            lambda: self.ingest.count_source_error("router_unreachable"),
            self.ingest.tick,
        )

    def start(self) -> None:
        """Open the session in the background: routers that are not up yet are retried until they are."""
        self._outbox.start()
        self.receiver.start()

    def stop(self) -> None:
        """Undeclare everything and close the session."""
        self.receiver.stop()
        self._outbox.close()

    def _on_sample(self, key: str, attachment: bytes | None, payload: bytes) -> None:
        self._outbox.put((SAMPLE, key, attachment, payload), attachment)

    def _on_token(self, key: str, alive: bool) -> None:
        self._outbox.put((TOKEN, key, alive))  # in order with the samples: a publisher's go after its last

    def _ingest(self, items: list[Item]) -> bool:
        self.ingest.on_items(items)
        return True
