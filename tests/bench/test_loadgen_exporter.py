"""The load generator end to end: 200 robots over Zenoh, through a router, to a real exporter.

What the generator publishes must be what an exporter takes for a fleet of rmw_zenoh robots: every
robot up with its 50 components, and the robots in trouble in ERROR.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from bench.loadgen import running_loadgen
from bench.loadgen_payloads import Fleet, FleetShape
from testbed.processes import running_exporter, wait_for
from testbed.zenoh import endpoint, exporter_args, running_router

pytestmark = pytest.mark.servers

ROBOTS = 200
ERROR = 2


def test_two_hundred_robots_are_heard_up_with_fifty_components_and_their_trouble(tmp_path: Path) -> None:
    troubled = {f"lg{robot + 1}" for robot in Fleet(FleetShape(robots=ROBOTS)).trouble}
    assert len(troubled) == 4  # 2 % of 200, drawn with the default seed
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

        def every_robot_heard() -> list[dict[str, object]] | None:
            robots: list[dict[str, object]] = exporter.get_json("/api/v1/robots")["robots"]
            heard = [r for r in robots if r["up"] and r["components"] == 50]
            return robots if len(heard) == ROBOTS else None

        robots = wait_for(every_robot_heard, 60, message=f"{ROBOTS} robots up with 50 components")
        assert {r["robot"] for r in robots} == {f"lg{i}" for i in range(1, ROBOTS + 1)}
        assert {r["robot"] for r in robots if r["level"] == ERROR} == troubled
        document = exporter.robot(sorted(troubled)[0])
        assert document is not None and document["transport"] == "zenoh"
        figures = loadgen.finish()
    assert figures.robots == ROBOTS and figures.published > 0 and figures.subscribed_after is not None
