"""Ingest workers over DDS: the exporter's one participant relays each worker its own robots' samples.

Every robot writes the one `rt/diagnostics`, as diagnostic_updater does (the load generator over real
Cyclone DDS on loopback, in a process of its own), and the ROS graph names each writer's node. A DDS
reader cannot take only some writers' samples: the exporter's participant takes them all, once, and each
worker receives only its robots' (so a worker divides the cost). The workers here are relayed sources in
this process, each with a model of its own, reading their pipes as worker processes do.
"""

from __future__ import annotations

import multiprocessing
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from bench.loadgen import running_loadgen
from overseer.codec.cdr import encode_diagnostic_array
from overseer.config.dds import DdsConfig, DomainConfig
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import FleetModel
from overseer.model.shard import Shard
from overseer.sources.dds.relay import DdsRelay
from overseer.sources.dds.relayed import RelayedDdsSource
from overseer.sources.zenoh.relay_items import CALL, SAMPLE, RelayedFeed
from overseer.sources.zenoh.shared_ring import SharedRing
from testbed.ports import fresh_domain_id
from testbed.processes import wait_for

ROBOTS = 12
WORKERS = 2
COMPONENTS = 10


def worker_shards() -> list[Shard]:
    """The parts of the fleet two workers follow."""
    return [Shard().for_worker(worker, WORKERS) for worker in range(WORKERS)]


@contextmanager
def relayed_workers(relay: DdsRelay) -> Iterator[list[tuple[RelayedDdsSource, FleetModel]]]:
    """Two relayed sources attached to `relay`, each with a model of its own, reading until the block ends."""
    workers = []
    for worker in range(WORKERS):
        reader, writer = multiprocessing.Pipe(duplex=False)
        ring = SharedRing.create()
        model = FleetModel()
        workers.append((RelayedDdsSource(model, RelayedFeed(reader, ring)), model))
        relay.attach(worker, RelayedFeed(writer, ring))
    for source, _ in workers:
        source.start()
    try:
        yield workers
    finally:
        relay.stop()
        for source, _ in workers:
            source.stop()


def robots_up(model: FleetModel) -> dict[str, bool]:
    """Each robot of a worker's model → whether it is up, with its components heard."""
    snapshot = model.snapshot()
    return {
        robot.name: snapshot.robot_up(robot) and len(robot.components) == COMPONENTS
        for robot in snapshot.robots
    }


def test_the_exporters_participant_takes_each_sample_once_and_each_worker_only_its_robots(
    tmp_path: Path,
) -> None:
    domain = fresh_domain_id()
    robots = {f"lg{index}" for index in range(1, ROBOTS + 1)}
    owned = [{name for name in robots if shard.owns(name)} for shard in worker_shards()]
    assert all(owned)  # the hash gives each worker some of them
    relay = DdsRelay(DdsConfig(domains=(DomainConfig(domain),), loopback_only=True), Shard(), WORKERS)
    with (
        relayed_workers(relay) as workers,
        running_loadgen(
            [
                f"--robots={ROBOTS}",
                f"--components={COMPONENTS}",
                "--namespace-prefix=lg",
                "--transport=dds",
                f"--domain={domain}",
                "--dds-shared-topic",
                "--rate=5",
                "--wait-for-subscribers=60",
            ],
            tmp_path,
        ) as loadgen,
    ):
        relay.start()
        loadgen.wait_ready(60)
        wait_for(
            lambda: all(
                robots_up(model) == dict.fromkeys(mine, True)
                for (_, model), mine in zip(workers, owned, strict=True)
            ),
            60,
            message="each worker's robots up, named by their nodes, and no other robot",
        )
        figures = loadgen.finish()
        # Every writer left with the generator: each robot is down at once in the worker that owns it.
        wait_for(
            lambda: not any(any(robots_up(model).values()) for _, model in workers),
            30,
            message="every robot down once its writer left",
        )
        heard = [source.samples_heard for source, _ in workers]
    assert sum(heard) <= figures.published  # none crossed into two workers
    assert sum(heard) >= figures.published - 2 * ROBOTS  # all but those written before the reader matched
    for worker, (samples, mine) in enumerate(zip(heard, owned, strict=True)):
        assert samples >= 0.5 * figures.published * len(mine) / ROBOTS, (worker, heard)


def test_the_relayed_source_decodes_samples_makes_the_models_calls_and_refuses_any_other() -> None:
    model = FleetModel()
    source = RelayedDdsSource(model, RelayedFeed(multiprocessing.Pipe(duplex=False)[0]))
    source.on_items(
        [
            (CALL, "register", ("robot1", "dds")),
            (CALL, "__class__", ()),
            (CALL, "publisher_left", ("robot1",)),
        ]
    )
    [robot] = model.snapshot().robots
    assert robot.name == "robot1" and not model.snapshot().robot_up(robot)
    source.on_items([(SAMPLE, ("robot1", "rt/diagnostics", "feed"), None, b"\x00\x01not an array")])
    assert dict(model.snapshot().message_counts)[("dds", "decode_error")] == 1


def status_array(message: str) -> bytes:
    """A serialized DiagnosticArray with one status saying `message`."""
    status = DiagnosticStatus(0, "battery", message, "hw", ())
    return encode_diagnostic_array(DiagnosticArray(0, 0, "", (status,)))


def test_a_worker_started_again_is_told_first_which_of_its_robots_have_writers() -> None:
    relay = DdsRelay(DdsConfig(), Shard(), 1)  # never joined: the test makes the source's calls
    relay.register("kept", "dds")
    relay.register("gone", "dds")
    relay.publisher_left("gone")  # its last writer left before the worker started again
    reader, writer = multiprocessing.Pipe(duplex=False)
    ring = SharedRing.create()
    model = FleetModel()
    worker = RelayedDdsSource(model, RelayedFeed(reader, ring))
    relay.attach(0, RelayedFeed(writer, ring))
    worker.start()
    try:
        wait_for(lambda: [r.name for r in model.snapshot().robots] == ["kept"], 10, message="kept registered")
    finally:
        relay.stop()
        worker.stop()


def test_a_sample_taken_before_its_writer_was_let_go_of_is_dropped_until_it_is_followed_again() -> None:
    model = FleetModel()
    worker = RelayedDdsSource(model, RelayedFeed(multiprocessing.Pipe(duplex=False)[0]))
    key = ("robot1", "rt/diagnostics", "rt/diagnostics@01")
    worker.on_items([(SAMPLE, key, None, status_array("first"))])
    worker.on_items([(CALL, "released", key), (SAMPLE, key, None, status_array("late"))])
    [robot] = model.snapshot().robots
    assert [component.message for component in robot.components.values()] == ["first"]
    # The writer's lease ran out and it came back: the source follows it again, with the same GUID.
    worker.on_items([(CALL, "followed", key), (SAMPLE, key, None, status_array("again"))])
    [robot] = model.snapshot().robots
    assert [component.message for component in robot.components.values()] == ["again"]
    assert worker.samples_heard == 3
