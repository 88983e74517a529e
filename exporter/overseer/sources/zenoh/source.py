"""The Zenoh transport in one process: robots on rmw_zenoh (ROS 2 Jazzy) and behind zenoh-bridge-ros2dds.

The exporter's session (`receiver.py`) hands every sample and token to the ingest (`ingest.py`), the
samples copied out of Zenoh between shares of the ingest's work so that Zenoh's channel stays short
while the ingest is behind (`paced_drain.drain_buffered`). Payloads
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
from overseer.sources.zenoh.receiver import ZenohReceiver


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
        self.receiver = ZenohReceiver(
            config,
            self.ingest.on_sample,
            self.ingest.on_token,
            lambda: self.ingest.count_source_error("router_unreachable"),
            self.ingest.tick,
            on_dropped=self.ingest.dropped_samples,
        )

    def start(self) -> None:
        """Open the session in the background: routers that are not up yet are retried until they are."""
        self.receiver.start()

    def stop(self) -> None:
        """Undeclare everything and close the session."""
        self.receiver.stop()
