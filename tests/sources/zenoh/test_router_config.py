"""The Zenoh router configuration Overseer ships: Zenoh reads it, and the tests' router runs with it.

Zenoh's default transmit queue (2 batches a priority, a sample dropped after 1 ms without room) lost
0.05-0.44 % of a 1,000-robot live fleet's samples towards the exporter on a busy 2-core machine
(`bench_live_values`, which compares both routers in one run); the shipped file's longer data queue lost
none. Every test and benchmark's router (`testbed/zenoh_router.py`) loads the shipped file, so what they
measure is what operators are told to run.
"""

from __future__ import annotations

import json
import re

import zenoh

from testbed.paths import REPO
from testbed.zenoh_router import SHIPPED_CONFIG, router_config

DATA_QUEUE = "transport/link/tx/queue/size/data"


def value(config: zenoh.Config, key: str) -> object:
    """One key of a Zenoh configuration, as Zenoh holds it."""
    return json.loads(config.get_json(key))


def shipped() -> zenoh.Config:
    """`deploy/zenoh/router.json5`, as Zenoh reads it."""
    return zenoh.Config.from_file(str(SHIPPED_CONFIG))


def test_the_shipped_router_configuration_is_a_router_with_a_longer_data_queue_than_zenohs_default() -> None:
    config = shipped()
    assert value(config, "mode") == "router"
    assert value(config, "scouting/multicast/enabled") is False
    assert value(config, DATA_QUEUE) == 16  # Zenoh's most
    assert value(config, DATA_QUEUE) > value(zenoh.Config(), DATA_QUEUE)  # type: ignore[operator]


def test_the_tests_router_runs_with_the_shipped_configuration_unless_told_zenohs_defaults() -> None:
    tests_router = router_config(7447)
    assert value(tests_router, DATA_QUEUE) == value(shipped(), DATA_QUEUE)
    assert value(tests_router, "listen/endpoints") == ["tcp/127.0.0.1:7447"]
    defaults = router_config(7447, zenoh_defaults=True)
    assert value(defaults, DATA_QUEUE) == value(zenoh.Config(), DATA_QUEUE)
    assert value(defaults, "mode") == "router"


def test_the_routers_networks_md_shows_are_zenoh_configurations_with_the_shipped_data_queue() -> None:
    text = (REPO / "docs" / "networks.md").read_text()
    routers = [block for block in re.findall(r"```json5\n(.*?)```", text, re.S) if '"router"' in block]
    assert len(routers) == 2  # the central router and a site's
    for block in routers:
        config = zenoh.Config.from_json5(block)
        assert value(config, DATA_QUEUE) == value(shipped(), DATA_QUEUE)
