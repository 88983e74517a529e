"""Ingest workers over Zenoh: each hears its own robots' samples only, so a worker divides the cost.

Two sources, as two ingest workers run them, follow one simulated fleet through a real router: each
model holds exactly the robots its worker owns, and each session receives only its robots' samples
(with the wildcard subscription of one worker, each would receive every sample and drop the others').
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from bench.bench_first_look import SampleBytes, ZenohSample
from overseer.codec.cdr import encode_diagnostic_array
from overseer.config.zenoh import ZenohConfig
from overseer.messages import DiagnosticArray
from overseer.model import FleetModel
from overseer.model.shard import Shard
from overseer.simulator.zenoh_publisher import attachment
from overseer.sources.topic_names import AGGREGATED
from overseer.sources.zenoh.keys import DIAGNOSTIC_ARRAY_HASH, data_key, publisher_gid, publisher_token
from overseer.sources.zenoh.source import ZenohSource
from testbed.processes import running_simulator, wait_for
from testbed.zenoh import endpoint, running_router, simulator_args

ROBOTS = 8
WORKERS = 2
QUEUE_LENGTH = 300  # samples a worker's queue holds in the test of a flood


def test_each_worker_receives_only_the_samples_of_the_robots_it_owns(tmp_path: Path) -> None:
    names = {f"robot{index}" for index in range(1, ROBOTS + 1)}
    shards = [Shard().for_worker(worker, WORKERS) for worker in range(WORKERS)]
    owned = [{name for name in names if shard.owns(name)} for shard in shards]
    assert all(owned)  # the hash gives each worker some of the eight
    with running_router(tmp_path) as port:
        config = ZenohConfig(enabled=True, mode="client", connect=(endpoint(port),))
        models = [FleetModel() for _ in shards]
        sources = [ZenohSource(config, model, shard) for model, shard in zip(models, shards, strict=True)]
        for source in sources:
            source.start()
        try:
            with running_simulator(tmp_path, 0, *simulator_args(port, f"--robots={ROBOTS}", "--rate=5")):

                def every_robot_heard() -> bool:
                    heard = [{robot.name for robot in model.snapshot().robots} for model in models]
                    return heard == owned and all(
                        robot.components for model in models for robot in model.snapshot().robots
                    )

                wait_for(every_robot_heard, 30, message="each worker's robots, and only those, heard")
                before = [source.samples_heard for source in sources]
                time.sleep(3)
                heard = [source.samples_heard - start for source, start in zip(sources, before, strict=True)]
        finally:
            for source in sources:
                source.stop()
    published = ROBOTS * 5 * 3  # robots x rate x seconds, roughly
    for worker, samples in enumerate(heard):
        share = len(owned[worker]) / ROBOTS
        # Its own robots' samples (give or take a publication at each end), never the whole fleet's.
        assert 0.6 * share * published <= samples <= 1.4 * share * published, (worker, samples, share)


def test_a_worker_whose_ingest_falls_behind_drops_and_counts_instead_of_growing() -> None:
    # Not started: nothing drains the queue, as when a flood outruns the ingest.
    model = FleetModel()
    shard = Shard().for_worker(0, WORKERS)
    source = ZenohSource(ZenohConfig(enabled=True, queue_length=QUEUE_LENGTH), model, shard)
    robot = next(name for name in (f"robot{index}" for index in range(1, 100)) if shard.owns(name))
    token = publisher_token(0, "1f", 10, robot, "aggregator", AGGREGATED, DIAGNOSTIC_ARRAY_HASH)
    payload = SampleBytes(encode_diagnostic_array(DiagnosticArray(0, 0, "", ())))

    def sample(number: int) -> Any:  # what the source reads of a zenoh.Sample, numbered as rmw_zenoh does
        gid = publisher_gid(token)
        return ZenohSample(data_key(0, robot, AGGREGATED), payload, SampleBytes(attachment(number, 0, gid)))

    source._on_data(sample(1))  # heard: the publisher's numbering starts there
    handler = source._queued()  # the handler every subscription of a worker is declared with
    for number in range(2, QUEUE_LENGTH + 7):
        handler(sample(number))
    assert model.snapshot().message_counts.get(("zenoh", "dropped")) == 5
    while (queued := source._samples.get_nowait() if not source._samples.empty() else None) is not None:
        source._on_data(queued)
    source._on_data(sample(QUEUE_LENGTH + 7))
    counts = model.snapshot().message_counts
    assert counts.get(("zenoh", "received")) == QUEUE_LENGTH + 2
    assert counts.get(("zenoh", "lost"), 0) == 0  # the five were heard, and counted dropped: not lost too
