"""Transports: each subscribes to robots' diagnostics and hands them to the fleet model."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:
    from overseer.config import Config
    from overseer.model import FleetModel
    from overseer.sources.zenoh.relay_items import RelayedFeed


class Source(Protocol):
    """A transport feeding the fleet model; `start` must not block, `stop` releases everything."""

    transport: str

    def start(self) -> None:
        """Begin receiving diagnostics in background threads."""

    def stop(self) -> None:
        """Stop receiving and release connections."""


def enabled_transports(config: Config) -> list[str]:
    """The names of the transports `config` enables, in the order `build_sources` creates them."""
    enabled = [
        ("dds", config.dds.enabled),
        ("ros1", config.ros1.enabled),
        ("zenoh", config.zenoh.enabled),
        ("ros2", config.ros2.enabled),
    ]
    return [name for name, on in enabled if on]


def build_sources(
    config: Config, model: FleetModel, relayed: Mapping[str, RelayedFeed] | None = None
) -> list[Source]:
    """The transports `config` enables, feeding `model` with the robots of `config.shard`; not started.

    `relayed`: by transport ("dds", "zenoh"), what an ingest worker reads from the exporter's relay of
    that transport, instead of a participant or session of its own.
    """
    relayed = relayed or {}
    sources: list[Source] = []
    if config.dds.enabled and "dds" in relayed:
        from overseer.sources.dds.relayed import RelayedDdsSource

        sources.append(RelayedDdsSource(model, relayed["dds"]))
    elif config.dds.enabled:
        from overseer.sources.dds.source import DdsSource

        sources.append(DdsSource(config.dds, model, config.shard, config.robot_namespace_depth))
    if config.ros1.enabled:
        from overseer.sources.ros1.source import Ros1Source

        robots = tuple(robot for robot in config.ros1.robots if config.shard.owns(robot.name))
        sources.append(Ros1Source(replace(config.ros1, robots=robots), model))
    if config.zenoh.enabled and "zenoh" in relayed:
        from overseer.sources.zenoh.relayed import RelayedZenohSource

        depth = config.robot_namespace_depth
        sources.append(RelayedZenohSource(config.zenoh, model, config.shard, relayed["zenoh"], depth))
    elif config.zenoh.enabled:
        from overseer.sources.zenoh.source import ZenohSource

        sources.append(ZenohSource(config.zenoh, model, config.shard, config.robot_namespace_depth))
    if config.ros2.enabled:
        from overseer.sources.ros2 import require_rclpy

        require_rclpy("ros2.enabled (--ros2)")
        from overseer.sources.ros2.source import Ros2Source, node_name

        name = node_name(config.ros2, config.shard.worker, config.shard.workers)
        sources.append(Ros2Source(config.ros2, model, name, config.shard, config.robot_namespace_depth))
    return sources
