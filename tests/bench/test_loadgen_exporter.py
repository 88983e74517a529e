"""The load generator end to end: 200 robots over Zenoh, through a router, and over DDS, to a real exporter.

What the generator publishes must be what an exporter takes for a fleet of rmw_zenoh robots, or of
robots whose diagnostic_updater writes the absolute `/diagnostics` over DDS: every robot up with its 50
components, and the robots in trouble in ERROR.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from bench.loadgen import running_loadgen
from bench.loadgen_payloads import Fleet, FleetShape
from testbed.ports import fresh_domain_id
from testbed.processes import Exporter, running_exporter, wait_for
from testbed.zenoh import endpoint, exporter_args, running_router

pytestmark = pytest.mark.servers

ROBOTS = 200
ERROR = 2


def test_two_hundred_robots_are_heard_up_with_fifty_components_and_their_trouble(tmp_path: Path) -> None:
    with (
        running_router(tmp_path) as port,
        running_exporter(tmp_path, None, *exporter_args(port)) as exporter,
        running_loadgen(
            [
                f"--robots={ROBOTS}",
                "--namespace-prefix=lg",
                f"--zenoh.connect={endpoint(port)}",
                "--zenoh.listen=tcp/127.0.0.1:0",
                "--wait-for-subscribers=60",
            ],
            tmp_path,
        ) as loadgen,
    ):
        loadgen.wait_ready(60)
        assert_fleet_heard(exporter, "zenoh")
        figures = loadgen.finish()
    assert figures.robots == ROBOTS and figures.published > 0 and figures.subscribed_after is not None


def test_robots_on_the_one_dds_diagnostics_topic_are_named_by_their_nodes_across_two_workers(
    tmp_path: Path,
) -> None:
    domain = fresh_domain_id()
    with (
        running_exporter(tmp_path, domain, "--ingest.workers=2") as exporter,
        running_loadgen(
            [
                f"--robots={ROBOTS}",
                "--namespace-prefix=lg",
                "--transport=dds",
                f"--domain={domain}",
                "--dds-shared-topic",
                "--wait-for-subscribers=60",
            ],
            tmp_path,
        ) as loadgen,
    ):
        loadgen.wait_ready(60)
        assert_fleet_heard(exporter, "dds")
        figures = loadgen.finish()
    assert figures.robots == ROBOTS and figures.published > 0 and figures.failed == 0


def assert_fleet_heard(exporter: Exporter, transport: str) -> None:
    """Every robot up with 50 components over `transport`, and those in trouble in ERROR."""
    troubled = {f"lg{robot + 1}" for robot in Fleet(FleetShape(robots=ROBOTS)).trouble}
    assert len(troubled) == 4  # 2 % of 200, drawn with the default seed

    def every_robot_heard() -> list[dict[str, object]] | None:
        robots: list[dict[str, object]] = exporter.get_json("/api/v1/robots")["robots"]
        heard = [r for r in robots if r["up"] and r["components"] == 50]
        return robots if len(heard) == ROBOTS else None

    robots = wait_for(every_robot_heard, 60, message=f"{ROBOTS} robots up with 50 components")
    assert {r["robot"] for r in robots} == {f"lg{i}" for i in range(1, ROBOTS + 1)}
    assert {r["robot"] for r in robots if r["level"] == ERROR} == troubled
    document = exporter.robot(sorted(troubled)[0])
    assert document is not None and document["transport"] == transport
