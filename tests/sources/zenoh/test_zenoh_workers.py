"""Ingest workers over Zenoh: the exporter's one session relays each worker its own robots' samples.

The fleet's samples cross into the exporter once, in its session, and each worker receives only its
robots' (so a worker divides the cost); the workers here are relayed sources in this process, each with a
model of its own, reading their pipes as worker processes do.
"""

from __future__ import annotations

import multiprocessing
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from overseer.codec.cdr import encode_diagnostic_array
from overseer.config.zenoh import ZenohConfig
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import FleetModel
from overseer.model.shard import Shard
from overseer.simulator.zenoh_publisher import attachment
from overseer.sources.topic_names import AGGREGATED, RAW
from overseer.sources.zenoh import outbox as outbox_module
from overseer.sources.zenoh import relay as relay_module
from overseer.sources.zenoh.keys import DIAGNOSTIC_ARRAY_HASH, data_key, publisher_gid, publisher_token
from overseer.sources.zenoh.relay import ZenohRelay
from overseer.sources.zenoh.relay_items import RelayedFeed
from overseer.sources.zenoh.relayed import RelayedZenohSource
from overseer.sources.zenoh.shared_ring import SharedRing
from testbed.processes import running_simulator, wait_for
from testbed.zenoh import endpoint, running_router, simulator_args

ROBOTS = 8
WORKERS = 2
QUEUE_LENGTH = 300  # samples that may wait for a worker, in the test of one that falls behind
FIRST, SECOND = "robot_a", "robot_d"  # of two workers, the first's robot and the second's


def relay_feeds(ring: bool = True) -> tuple[RelayedFeed, RelayedFeed]:
    """A worker's end and the relay's of a new pipe, with a ring of shared memory (as a pool makes them)."""
    reader, writer = multiprocessing.Pipe(duplex=False)
    shared = SharedRing.create() if ring else None
    return RelayedFeed(reader, shared), RelayedFeed(writer, shared)


def worker_shards() -> list[Shard]:
    """The parts of the fleet two workers follow."""
    return [Shard().for_worker(worker, WORKERS) for worker in range(WORKERS)]


@contextmanager
def relayed_workers(relay: ZenohRelay, config: ZenohConfig) -> Iterator[list[RelayedZenohSource]]:
    """Two relayed sources attached to `relay`, each with a model of its own, reading until the block ends."""
    sources = []
    for worker, shard in enumerate(worker_shards()):
        reader, writer = relay_feeds()
        sources.append(RelayedZenohSource(config, FleetModel(), shard, reader))
        relay.attach(worker, writer)
    for source in sources:
        source.start()
    try:
        yield sources
    finally:
        relay.stop()
        for source in sources:
            source.stop()


def components(source: RelayedZenohSource) -> dict[str, list[str]]:
    """Robot → its components' names, in a relayed source's model."""
    snapshot = source.ingest._model.snapshot()
    return {robot.name: [name for name, _ in robot.components] for robot in snapshot.robots}


def test_the_exporters_session_hears_each_sample_once_and_each_worker_only_its_robots(tmp_path: Path) -> None:
    robots = {f"robot{index}" for index in range(1, ROBOTS + 1)}
    owned = [{name for name in robots if shard.owns(name)} for shard in worker_shards()]
    assert all(owned)  # the hash gives each worker some of the eight
    with running_router(tmp_path) as port:
        config = ZenohConfig(enabled=True, mode="client", connect=(endpoint(port),))
        relay = ZenohRelay(config, Shard(), WORKERS)
        with relayed_workers(relay, config) as workers:
            relay.start()
            with running_simulator(tmp_path, 0, *simulator_args(port, f"--robots={ROBOTS}", "--rate=5")):

                def every_robot_heard_by_its_worker() -> bool:
                    heard = [components(worker) for worker in workers]
                    return [set(robots) for robots in heard] == owned and all(
                        names for robots in heard for names in robots.values()
                    )

                wait_for(every_robot_heard_by_its_worker, 30, message="each worker's robots, and only those")
                before = relay.receiver.samples_heard, [worker.samples_heard for worker in workers]
                time.sleep(3)
                heard = relay.receiver.samples_heard - before[0]
                relayed = [
                    worker.samples_heard - start for worker, start in zip(workers, before[1], strict=True)
                ]
    published = ROBOTS * 5 * 3  # robots x rate x seconds, roughly
    assert 0.6 * published <= heard <= 1.4 * published  # once, in the exporter's session
    assert sum(relayed) == pytest.approx(heard, abs=2 * ROBOTS)  # each sample to exactly one worker
    for worker, samples in enumerate(relayed):
        share = len(owned[worker]) / ROBOTS
        assert 0.6 * share * published <= samples <= 1.4 * share * published, (worker, samples, share)


def updater_token(robot: str, entity: int) -> str:
    """The token of a diagnostic_updater node of `robot` publishing on the absolute /diagnostics."""
    return publisher_token(0, "1f", entity, robot, "driver", RAW, DIAGNOSTIC_ARRAY_HASH, topic_namespace="")


def array(name: str) -> bytes:
    """A DiagnosticArray with one status."""
    return encode_diagnostic_array(DiagnosticArray(0, 0, "", (DiagnosticStatus(0, name, "ok", "hw", ()),)))


def test_un_namespaced_samples_go_to_their_robots_worker_and_a_worker_started_again_gets_the_tokens() -> None:
    config = ZenohConfig(enabled=True)
    relay = ZenohRelay(config, Shard(), WORKERS)  # its session is never opened: the test hands it samples
    assert [Shard().worker_of(name, WORKERS) for name in (FIRST, SECOND)] == [0, 1]
    tokens = {name: updater_token(name, entity) for entity, name in enumerate((FIRST, SECOND), start=10)}
    key = data_key(0, "", RAW)  # diagnostic_updater's absolute /diagnostics: one key for every robot

    def publish(name: str, number: int) -> None:
        relay.on_sample(key, attachment(number, 0, publisher_gid(tokens[name])), array(f"driver: {name}"))

    with relayed_workers(relay, config) as workers:
        publish(SECOND, 1)  # before its token: every worker holds it until the token says whose it is
        for token in tokens.values():
            relay.on_token(token, True)
        publish(FIRST, 1)
        publish(SECOND, 2)
        expected = [{FIRST: [f"driver: {FIRST}"]}, {SECOND: [f"driver: {SECOND}"]}]
        wait_for(lambda: [components(worker) for worker in workers] == expected, 5, message="each its own")
        assert [worker.samples_heard for worker in workers] == [2, 2]  # the held one, then its own
        # The second worker starts again: the relay tells it the tokens alive before any sample.
        reader, writer = relay_feeds()
        restarted = RelayedZenohSource(config, FleetModel(), worker_shards()[1], reader)
        relay.attach(1, writer)
        restarted.start()
        try:
            publish(SECOND, 3)
            # Attributed at once, not held for the 3 s grace and then given to the domain's robot.
            wait_for(lambda: components(restarted) == expected[1], 2, message="its robot's sample")
        finally:
            restarted.stop()


def test_samples_beyond_what_may_wait_for_a_worker_are_dropped_and_counted_not_lost() -> None:
    config = ZenohConfig(enabled=True, queue_length=QUEUE_LENGTH)
    relay = ZenohRelay(config, Shard(), 1)
    token = publisher_token(0, "1f", 10, FIRST, "aggregator", AGGREGATED, DIAGNOSTIC_ARRAY_HASH)
    key, gid = data_key(0, FIRST, AGGREGATED), publisher_gid(token)
    status = DiagnosticStatus(0, "/burst", "ok", "", tuple((f"key{i}", "x" * 90) for i in range(50)))
    payload = encode_diagnostic_array(DiagnosticArray(0, 0, "", (status,)))  # 5 kB: the pipe fills
    reader, writer = relay_feeds(ring=False)  # what waits is bounded by the queue and the pipe alone
    relay.attach(0, writer)
    sent = 10 * QUEUE_LENGTH
    for number in range(1, sent + 1):  # nothing reads the pipe yet: a worker far behind
        relay.on_sample(key, attachment(number, 0, gid), payload)
    worker = RelayedZenohSource(config, FleetModel(), Shard(), reader)
    worker.start()
    model = worker.ingest._model

    def counted() -> list[int]:  # received, dropped, lost
        counts = model.snapshot().message_counts
        return [counts.get(("zenoh", result), 0) for result in ("received", "dropped", "lost")]

    try:
        wait_for(lambda: sum(counted()) == sent, 10, message="the flood received or counted dropped")
        relay.on_sample(key, attachment(sent + 1, 0, gid), payload)  # after the flood, numbered on
        wait_for(lambda: sum(counted()) == sent + 1, 10, message="the sample after the flood")
        received, dropped, lost = counted()
    finally:
        relay.stop()
        worker.stop()
    assert dropped >= sent - 3 * QUEUE_LENGTH  # what waited, what the pipe held and one batch at most
    assert received == sent + 1 - dropped
    assert lost == 0  # the dropped were counted as such, not as lost as well


def test_a_flood_of_tokens_to_a_worker_that_is_stuck_is_bounded(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(relay_module, "MAX_LIVE_TOKENS", 10)
    monkeypatch.setattr(outbox_module, "MAX_TOKENS", 10)
    relay = ZenohRelay(ZenohConfig(enabled=True, queue_length=5), Shard(), 1)
    _, writer = relay_feeds(ring=False)  # nothing ever reads it: a worker that is stuck
    relay.attach(0, writer)
    for entity in range(1000):  # tokens come and go faster than anyone could follow
        relay.on_token(updater_token(f"robot{entity}", entity), alive=entity % 2 == 0)
    outbox = relay._outboxes[0]
    assert outbox is not None
    assert len(outbox._items) <= 5 + 10  # what may wait, beside one batch in the pipe
    assert outbox._tokens_dropped > 900
    relay.stop()
