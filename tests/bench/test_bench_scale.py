"""The scale benchmark at its smallest, with a fleet shaped by its options, to a real router and exporter.

Others run `bench_scale` with fleets of their own (sizes, rates, change and trouble shares): what it
asks the generator for must be what it measures and labels.
"""

from __future__ import annotations

import pytest

from bench.bench_scale import STORES, run, shard_of
from bench.common import Row
from bench.loadgen_payloads import FleetShape
from bench.scale_icinga2 import failed_requests
from bench.worker_cpu import (
    BUSIEST_WORKER_A_MESSAGE,
    OWN_PROCESS_A_MESSAGE,
    STEADY_CPU_A_MESSAGE,
)
from overseer.model.shard import Shard

pytestmark = pytest.mark.servers

ROBOTS = 20
COMPONENTS = 20
RATE = 2.0
SECONDS = 16.0


def test_a_small_fleet_at_two_hertz_is_published_measured_and_labelled_as_asked() -> None:
    shape = FleetShape(robots=ROBOTS, components=COMPONENTS, change_share=0.05)
    rows = {row.figure: row for row in run(shape, workers=1, seconds=SECONDS, rate=RATE, floor=True)}
    label = "20 robots x 20 at 2 Hz, realistic, 5.00% of statuses changing a second, zenoh, 1 worker"

    def row(figure: str) -> Row:
        return rows[f"{label}: {figure}"]

    expected = ROBOTS * RATE * SECONDS
    published = next(row for figure, row in rows.items() if figure.startswith(f"{label}: published"))
    assert 0.9 * expected <= published.value <= 1.05 * expected, rows.keys()
    assert row("lost updates").value == 0 and row("lost updates").met
    assert row("of which the exporter counted lost").value == 0
    assert row("of which the exporter heard and dropped").value == 0
    # The subscriber that only counts heard the same fleet through the same router.
    assert row("lost by a subscriber that only counts (same router, same run)").value == 0
    assert row("lost beyond it").value == 0 and row("lost beyond it").met
    assert row("exporter CPU a message").value > 0
    # one worker ingests in the exporter's own process: no part of it is told apart
    assert row(STEADY_CPU_A_MESSAGE).value >= 0
    assert not any(OWN_PROCESS_A_MESSAGE in figure or BUSIEST_WORKER_A_MESSAGE in figure for figure in rows)
    memory = row("exporter memory a component (resident, all its processes)")
    assert memory.unit == "bytes" and memory.value > 0 and memory.target == "<= 1000"
    # shared pages (the interpreter, the libraries) counted once: less than each process counting them
    assert 0 < row("proportional (PSS: pages the processes share counted once)").value < memory.value
    assert row("the most in the steady window (read every second)").value > 0
    # what the fleet added: far less than the whole at this size, the processes' own memory left out
    beyond = next(r for figure, r in rows.items() if figure.startswith(f"{label}: of which beyond its"))
    assert 0 < beyond.value < memory.value / 2, (beyond.figure, beyond.value)
    assert beyond.figure.endswith(" MB following no robot)")
    assert row("changes timed").value >= SECONDS / 2  # the probe, with the fleet's components, once a second
    assert (
        0 < row("a change to /metrics, p99 (the whole window)").value < 5
    )  # measured (the target is the bench's)
    assert 0 <= row("the first look (until changes take under 1 s)").value < SECONDS
    after = next(row for figure, row in rows.items() if "after the first look, p99" in figure)
    assert 0 < after.value < 5 and after.target == "<= 1"
    assert not any("status page" in figure for figure in rows)  # only when asked for


def test_the_status_page_and_the_api_are_timed_while_the_fleet_goes_on_publishing() -> None:
    shape = FleetShape(robots=ROBOTS, components=COMPONENTS)
    rows = {row.figure: row for row in run(shape, workers=2, seconds=SECONDS / 2, page=True)}
    label = "20 robots x 20, realistic, zenoh, 2 workers"

    def row(figure: str) -> Row:
        return rows[f"{label}: {figure}"]

    for view in ("fleet view", "one robot"):
        first_render = row(f"status page first render, {view}")
        assert 0 < first_render.value < 10_000 and first_render.target == "<= 1000"
    robots = next(row for figure, row in rows.items() if "GET /api/v1/robots (" in figure)
    assert 0 < robots.value < 10_000 and robots.unit == "ms"
    assert 0 < row("GET /api/v1/events?limit=100 (the newest events)").value < 10_000
    assert row("lost updates").value == 0  # the generator was stopped, not cut off, after the page
    # two workers: the exporter's own process and the busier of them, parts of the whole (same readings)
    own, busiest = row(OWN_PROCESS_A_MESSAGE).value, row(BUSIEST_WORKER_A_MESSAGE).value
    assert own >= 0 and busiest >= 0 and own + busiest <= row(STEADY_CPU_A_MESSAGE).value + 1e-9


def test_a_tiny_fleet_on_four_workers_is_heard_whole_with_its_probe_robot() -> None:
    # The benchmark gave the exporter a robot cap of twice the fleet, which each worker held a share of
    # then (one robot each): the fleet's two robots and the probe did not fit. The exporter's own fix,
    # the cap counted across workers, is tested in tests/fleet/test_ingest_workers.py.
    shape = FleetShape(robots=2, components=COMPONENTS)
    rows = {row.figure: row for row in run(shape, workers=4, seconds=SECONDS / 2)}
    label = "2 robots x 20, realistic, zenoh, 4 workers"

    def row(figure: str) -> Row:
        return rows[f"{label}: {figure}"]

    assert row("statuses dropped beyond fleet.max_robots").value == 0
    assert row("statuses dropped beyond fleet.max_robots").met
    assert row("lost updates").value == 0
    assert row("changes timed").value >= SECONDS / 4  # the probe robot was followed


@pytest.mark.parametrize("store", STORES)
def test_two_shards_share_the_fleet_and_an_agent_sends_their_scrapes_to_one_store(store: str) -> None:
    # Issue 32's sharded layout: two exporters (`--shard 0/2`, `1/2`) on the same router, scraped by a
    # Prometheus in agent mode whose remote_write fills a store (a Prometheus, VictoriaMetrics), which the
    # figures are read from.
    shape = FleetShape(robots=ROBOTS, components=COMPONENTS)
    rows = {
        row.figure: row
        for row in run(
            shape, workers=1, seconds=SECONDS / 2, prometheus_seconds=30, interval=5, shards=2, store=store
        )
    }
    label = "20 robots x 20, realistic, zenoh, 1 worker in each of 2 shards"
    label += f", Prometheus in agent mode into {store}"

    def row(figure: str) -> Row:
        return rows[f"{label}: {figure}"]

    # Every robot followed by exactly one shard: the fleet and the probe, none twice, none lost.
    assert row("robots followed (the probe's included)").value == ROBOTS + 1
    assert row("robots followed by more than one shard").value == 0
    assert row("robots followed by more than one shard").met
    assert row("lost updates").value == 0
    assert row("changes timed").value >= SECONDS / 4  # the probe read from the shard that follows it
    # The store holds both shards' scrapes, sent by the agent: two targets' worth in 30 s at 5 s.
    scrapes = row("Prometheus: scrapes measured, exporter / floor")
    assert scrapes.value >= 2 * 3 and scrapes.unit.removeprefix("/ ").isdigit(), scrapes
    assert int(scrapes.unit.removeprefix("/ ")) >= 2 * 3
    assert row("Prometheus: exporter scrapes failed").value == 0
    assert row("Prometheus: exporters scraped").value == 2  # both shards' series reached the store
    assert row("Prometheus: samples a scrape").value > ROBOTS * COMPONENTS  # a level a component, and more
    assert 0 < row("Prometheus: exporter / floor").value < 20


def test_the_probe_check_and_page_read_the_shard_that_follows_their_robot() -> None:
    shards = ["shard0", "shard1", "shard2"]
    robots = ["probe", "robot1", *(f"robot{n}" for n in range(2, 40))]
    for robot in robots:
        (owner,) = [shard for index, shard in enumerate(shards) if Shard(index, 3).owns(robot)]
        assert shard_of(shards, robot) == owner
    assert {shard_of(shards, robot) for robot in robots} == set(shards)


def test_the_fleet_pushed_to_a_real_icinga2_is_counted_as_icinga_received_it() -> None:
    shape = FleetShape(robots=ROBOTS, components=COMPONENTS)
    # Long enough for Icinga's last minute to be one of pushing every robot, registered in the first seconds.
    rows = {row.figure: row for row in run(shape, workers=2, seconds=75.0, icinga2_interval=10.0)}
    label = "20 robots x 20, realistic, zenoh, 2 workers"

    def row(figure: str) -> Row:
        return rows[f"{label}: Icinga 2 push every 10 s: {figure}"]

    # A host, its robot service and a service a group (five) for each robot and the probe's.
    assert row("hosts and services registered").value == (ROBOTS + 1) * 7
    assert row("config package stages (registering robots and their groups)").value >= 1
    received = row("of those due a minute (every object once an interval)")
    assert received.met and received.value >= 0.95, received
    assert row("requests failed").value == 0 and row("requests failed").met
    assert row("Icinga 2's CPU").value > 0


def test_failed_pushes_are_told_by_reason_for_the_row_to_say_why() -> None:
    metrics = "\n".join(
        [
            'overseer_icinga2_pushes_total{result="ok"} 4518.0',
            'overseer_icinga2_pushes_total{result="tls"} 1.0',
            'overseer_icinga2_pushes_total{result="http_500"} 2.0',
            'overseer_icinga2_pushes_total{result="timeout"} 0.0',
            'overseer_icinga2_package_stages_total{result="tls"} 7.0',
        ]
    )
    assert failed_requests(metrics) == {"tls": 1.0, "http_500": 2.0}
