"""A robot's first look by the exporter with 1,000 robots known and with 10,000: it must not grow with them.

When the exporter starts beside a running fleet, every robot is new within a second, so whatever a
new robot costs per robot already known is paid squared: 10,000 robots took 12 s of CPU to be first
heard over Zenoh (each new feed looked through every feed of the fleet) while their next arrays were
queuing. In process, no network: the Zenoh source is handed each robot's first sample with the
values the session reads of it (key, attachment, payload), and the DDS source adopts each robot's
`/diagnostics_agg` writer as discovery does. The figure is the last 1,000 robots' cost at each size;
the target is their ratio, measured in the same run.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from functools import partial
from typing import Any

from bench.common import Row, emit
from bench.loadgen_payloads import Fleet, FleetShape
from overseer.config.dds import DdsConfig, DomainConfig
from overseer.config.zenoh import ZenohConfig
from overseer.model import FleetLimits, FleetModel
from overseer.simulator.zenoh_publisher import attachment
from overseer.sources.dds.source import DdsSource, _DomainSession, _Writer
from overseer.sources.robot_naming import RobotNaming
from overseer.sources.topic_names import AGGREGATED, dds_topic_name
from overseer.sources.zenoh.keys import DIAGNOSTIC_ARRAY_HASH, data_key, publisher_gid, publisher_token
from overseer.sources.zenoh.source import ZenohSource

SIZES = (1_000, 10_000)
MEASURED = 1_000  # the last robots of each size, whose cost is the figure
TARGET_RATIO = 1.5


def aggregator_addresses(robots: int) -> list[tuple[str, bytes]]:
    """Each robot's key and attachment as its aggregator publishes on rmw_zenoh (robot00000 ... first)."""
    addresses = []
    for index in range(robots):
        name = f"robot{index:05d}"
        token = publisher_token(0, "1f", index, name, "aggregator", AGGREGATED, DIAGNOSTIC_ARRAY_HASH)
        addresses.append((data_key(0, name, AGGREGATED), attachment(1, 0, publisher_gid(token))))
    return addresses


def zenoh_first_arrays(robots: int) -> float:
    """Seconds a robot for the last `MEASURED` of `robots` robots' first arrays through the Zenoh source."""
    payloads = Fleet(FleetShape(robots)).payloads
    source = ZenohSource(ZenohConfig(enabled=True), FleetModel(FleetLimits(max_robots=2 * robots)))
    addresses = aggregator_addresses(robots)
    on_sample = source.ingest.on_sample  # handed what the session reads of each zenoh.Sample
    return _timed_tail(
        [
            partial(on_sample, key, robot_attachment, bytes(payload))
            for (key, robot_attachment), payload in zip(addresses, payloads, strict=True)
        ]
    )


def dds_writers_adopted(robots: int) -> float:
    """Seconds a robot for the last `MEASURED` of `robots` robots' aggregator writers adopted over DDS."""
    source = DdsSource(DdsConfig(), FleetModel(FleetLimits(max_robots=2 * robots)))
    no_entity: Any = None  # nothing here reaches the middleware
    session = _DomainSession(DomainConfig(0), RobotNaming("domain0", False, 1), *[no_entity] * 4)
    source._sessions.append(session)
    steps: list[Callable[[], object]] = []
    for index in range(robots):
        topic = dds_topic_name(f"robot{index:05d}", AGGREGATED)
        writer = _Writer(topic, AGGREGATED, index.to_bytes(16, "big"), None, 0.0)
        steps.append(partial(_discovered, source, session, index, writer))
    return _timed_tail(steps)


def _discovered(source: DdsSource, session: _DomainSession, handle: int, writer: _Writer) -> None:
    """What discovery does with a namespaced writer: remember it, then follow its robot."""
    session.writers[handle] = writer
    source._adopt(writer, writer.topic.split("/")[1])


def _timed_tail(steps: list[Callable[[], object]]) -> float:
    for step in steps[:-MEASURED]:
        step()
    started = time.process_time()
    for step in steps[-MEASURED:]:
        step()
    return (time.process_time() - started) / MEASURED


def main() -> None:
    """Measure and print the rows."""
    rows = []
    for label, measure in (
        ("Zenoh: first array", zenoh_first_arrays),
        ("DDS: writer adopted", dds_writers_adopted),
    ):
        seconds = {size: min(measure(size) for _ in range(3)) for size in SIZES}
        for size in SIZES:
            rows.append(Row("first_look", f"{label}, {size:,} robots", seconds[size] * 1e6, "µs a robot"))
        ratio = seconds[SIZES[-1]] / seconds[SIZES[0]]
        figure = f"{label}: {SIZES[-1]:,} robots against {SIZES[0]:,}"
        rows.append(Row("first_look", figure, ratio, "x", f"<= {TARGET_RATIO}", ratio <= TARGET_RATIO))
    emit(rows)


if __name__ == "__main__":
    main()
