"""A robot whose last publisher left stays down, whatever samples of that publisher were still waiting.

Tokens reach the source at once; samples may wait in a queue behind an ingest that is seconds behind (a
large fleet's first seconds). In process, no network: the source is handed what Zenoh hands it, a
publisher's token put and deleted and its samples, in the order a backlog delivers them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import zenoh

from bench.bench_first_look import SampleBytes, ZenohSample
from overseer.codec.cdr import encode_diagnostic_array
from overseer.config.zenoh import ZenohConfig
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import FleetModel
from overseer.simulator.zenoh_publisher import attachment
from overseer.sources.topic_names import AGGREGATED
from overseer.sources.zenoh.keys import DIAGNOSTIC_ARRAY_HASH, data_key, publisher_gid, publisher_token
from overseer.sources.zenoh.source import ZenohSource

PAYLOAD = SampleBytes(
    encode_diagnostic_array(DiagnosticArray(0, 0, "", (DiagnosticStatus(0, "/a", "ok", "", ()),)))
)


@dataclass(frozen=True)
class TokenSample:
    """What the Zenoh source reads of a liveliness sample."""

    key_expr: str
    kind: zenoh.SampleKind


class Robot:
    """One robot's aggregator as the source hears it: its token and its numbered samples."""

    def __init__(self, source: ZenohSource, name: str, node_id: int) -> None:
        self.source, self.name = source, name
        self.token = publisher_token(0, "1f", node_id, name, "aggregator", AGGREGATED, DIAGNOSTIC_ARRAY_HASH)
        self.number = 0

    def token_put(self) -> None:
        """Its token declared (the publisher started, or its link is back)."""
        self._on_token(zenoh.SampleKind.PUT)

    def token_deleted(self) -> None:
        """Its token gone (the process killed, or its link lost)."""
        self._on_token(zenoh.SampleKind.DELETE)

    def _on_token(self, kind: zenoh.SampleKind) -> None:
        token: Any = TokenSample(self.token, kind)  # what the source reads of a zenoh.Sample
        self.source._on_token(token)

    def sample(self) -> Any:
        """Its next sample, numbered (what the source reads of a zenoh.Sample)."""
        self.number += 1
        gid = publisher_gid(self.token)
        return ZenohSample(
            data_key(0, self.name, AGGREGATED), PAYLOAD, SampleBytes(attachment(self.number, 0, gid))
        )


def up(model: FleetModel, name: str) -> bool:
    """Whether the model has the robot up now."""
    snapshot = model.snapshot()
    robot = snapshot.find(name)
    return robot is not None and snapshot.robot_up(robot)


def test_samples_read_after_the_last_publisher_left_do_not_bring_its_robot_back_up() -> None:
    model = FleetModel()
    source = ZenohSource(ZenohConfig(enabled=True), model)
    robot = Robot(source, "gone", 10)
    robot.token_put()
    source._on_data(robot.sample())
    assert up(model, "gone")
    waiting = [robot.sample(), robot.sample()]  # published, then queued behind the ingest
    robot.token_deleted()  # the process killed: its token goes at once
    assert not up(model, "gone")
    for sample in waiting:
        source._on_data(sample)
    assert not up(model, "gone")
    assert model.snapshot().message_counts[("zenoh", "received")] == 3  # heard, and not taken for life
    robot.token_put()  # the link back: the same publisher declares its token again
    source._on_data(robot.sample())
    assert up(model, "gone")


def test_a_departed_publishers_samples_still_count_while_its_robot_has_another() -> None:
    model = FleetModel()
    source = ZenohSource(ZenohConfig(enabled=True), model)
    leaving, staying = Robot(source, "pair", 10), Robot(source, "pair", 11)
    leaving.token_put()
    staying.token_put()
    source._on_data(staying.sample())
    waiting = leaving.sample()
    leaving.token_deleted()
    source._on_data(waiting)  # its last status, from a robot that is still up: taken
    assert up(model, "pair")
    assert model.snapshot().message_counts[("zenoh", "received")] == 2
