"""Samples the exporter's own queue dropped: counted dropped for its own robots, never lost as well."""

from __future__ import annotations

from overseer.codec.cdr import encode_diagnostic_array
from overseer.config.zenoh import ZenohConfig
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import FleetModel
from overseer.model.shard import Shard
from overseer.simulator.zenoh_publisher import attachment
from overseer.sources.zenoh.keys import data_key
from overseer.sources.zenoh.source import ZenohSource

PAYLOAD = encode_diagnostic_array(DiagnosticArray(0, 0, "", (DiagnosticStatus(0, "/motor", "ok", "", ()),)))
SHARD = Shard(0, 2)


def robot_of(owned: bool) -> str:
    """A robot name this exporter's shard follows, or one another shard does."""
    return next(name for name in (f"robot{index}" for index in range(100)) if SHARD.owns(name) == owned)


def counts(model: FleetModel) -> dict[str, int]:
    """The Zenoh message counts by result."""
    return {result: count for (transport, result), count in model.snapshot().message_counts.items()}


def test_dropped_samples_of_its_robots_count_as_dropped_not_lost_and_other_shards_robots_not_at_all() -> None:
    model = FleetModel()
    ingest = ZenohSource(ZenohConfig(enabled=True), model, SHARD).ingest
    ours, theirs = robot_of(True), robot_of(False)
    gid = bytes(range(16))
    our_key, their_key = data_key(0, ours, "diagnostics_agg"), data_key(0, theirs, "diagnostics_agg")
    ingest.on_sample(our_key, attachment(1, 0, gid), PAYLOAD)
    ingest.dropped_samples([(our_key, attachment(n, 0, gid)) for n in (2, 3)] + [(their_key, None)])
    ingest.on_sample(our_key, attachment(4, 0, gid), PAYLOAD)
    assert counts(model) == {"received": 2, "dropped": 2}
