"""Where the DDS source's robots go: the model of its own process, or the ingest workers' through a relay.

The source decides which writer is which robot's; a sink is what it then does to the fleet: the model's
calls it makes (a robot registered, a topic or feed forgotten, a robot's last writer gone, counts), and
one ingest per writer it follows, which takes that writer's serialized samples.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Protocol

from overseer.codec import DecodeError, cdr
from overseer.ingest.payload import PayloadIngest
from overseer.model import FleetModel

log = logging.getLogger(__name__)

TRANSPORT = "dds"

Ingest = Callable[[bytes], object]  # takes one serialized DiagnosticArray (DecodeError when it is not one)


class DdsSink(Protocol):
    """What the DDS source does to the fleet, robot by robot."""

    def count_message(self, transport: str, result: str, count: int = 1) -> None:
        """Count messages by their result (a sample Cyclone could not deserialize: decode_error)."""

    def count_source_error(self, transport: str, reason: str) -> None:
        """Count one failure of the transport (a peer not resolved, a node's invalid namespace)."""

    def register(self, robot: str, transport: str) -> bool:
        """Make a discovered robot known before its first message; False when the robot cap refuses it."""

    def forget_topic(self, robot: str, topic: str) -> None:
        """Drop what `robot` said on `topic` (its raw diagnostics, once it has an aggregator)."""

    def forget_feed(self, robot: str, feed: str, last: bool) -> None:
        """Drop what `feed` told of `robot`: the feed's writer turned out to be another robot's."""

    def publisher_left(self, robot: str) -> None:
        """`robot`'s last diagnostics writer left: it is down from now on."""

    def ingest(self, robot: str, topic: str, feed: str) -> Ingest:
        """What takes the samples of `robot`'s writer `feed` of `topic`, from now on."""

    def released(self, robot: str, topic: str, feed: str) -> None:
        """The ingest given for `robot`'s `feed` is fed no more (its writer left, moved or is ignored)."""


class ModelSink:
    """The DDS source's robots in the model of its own process: each writer's samples decoded right there."""

    def __init__(self, model: FleetModel) -> None:
        """Feed `model`."""
        self._model = model

    def count_message(self, transport: str, result: str, count: int = 1) -> None:
        """Count messages in the model."""
        self._model.count_message(transport, result, count)

    def count_source_error(self, transport: str, reason: str) -> None:
        """Count a transport's failure in the model."""
        self._model.count_source_error(transport, reason)

    def register(self, robot: str, transport: str) -> bool:
        """Register the robot in the model (False at its robot cap)."""
        return self._model.register(robot, transport)

    def forget_topic(self, robot: str, topic: str) -> None:
        """Forget the robot's topic in the model."""
        self._model.forget_topic(robot, topic)

    def forget_feed(self, robot: str, feed: str, last: bool) -> None:
        """Forget the robot's feed in the model."""
        self._model.forget_feed(robot, feed, last)

    def publisher_left(self, robot: str) -> None:
        """Mark the robot down in the model."""
        self._model.publisher_left(robot)

    def ingest(self, robot: str, topic: str, feed: str) -> Ingest:
        """A payload ingest of the writer's samples into the model."""
        return PayloadIngest(self._model, robot, TRANSPORT, topic, cdr.WIRE_FORMAT, feed)

    def released(self, robot: str, topic: str, feed: str) -> None:
        """Nothing: the ingest goes with the writer that held it."""


def take_sample(ingest: Ingest, payload: bytes, topic: str) -> None:
    """Hand one sample of `topic` to its writer's ingest; one that does not decode is counted and said."""
    try:
        ingest(payload)
    except DecodeError as error:
        log.debug("undecodable sample on %s: %s", topic, error)
