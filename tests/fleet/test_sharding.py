"""Sharding: several exporters share one fleet; every robot is followed by exactly one of them."""

from __future__ import annotations

from pathlib import Path

import pytest

from overseer.config import ConfigError
from overseer.config.fleet import parse_shard
from overseer.model.shard import Shard
from testbed.processes import running_exporter, running_simulator, wait_for


@pytest.mark.parametrize("count", [1, 2, 3, 7])
def test_every_robot_belongs_to_exactly_one_shard(count: int) -> None:
    names = [f"robot{i}" for i in range(500)] + ["site_a/robot7", "ロボット", ""]
    for name in names:
        assert sum(Shard(index, count).owns(name) for index in range(count)) == 1


def test_shards_are_balanced_enough() -> None:
    owned = [sum(Shard(index, 4).owns(f"robot{i}") for i in range(4000)) for index in range(4)]
    assert min(owned) > 850


@pytest.mark.parametrize("text", ["2/2", "1", "a/b", "-1/2", "1/0"])
def test_bad_shard_is_a_config_error(text: str) -> None:
    with pytest.raises(ConfigError, match="shard: expected i/n"):
        parse_shard(text)


@pytest.mark.servers
def test_two_exporter_shards_split_a_fleet_without_overlap(tmp_path: Path, dds_domain: int) -> None:
    robots = {f"robot{i}" for i in range(1, 9)}
    expected = [{r for r in robots if Shard(i, 2).owns(r)} for i in range(2)]
    assert all(expected), "the test fleet must land on both shards"
    with (
        running_exporter(tmp_path, dds_domain, "--shard=0/2") as first,
        running_exporter(tmp_path, dds_domain, "--shard=1/2") as second,
        running_simulator(tmp_path, dds_domain, "--robots=8"),
    ):
        for exporter, names in zip((first, second), expected, strict=True):
            seen = wait_for(
                lambda e=exporter, n=names: (
                    (s := {r["robot"] for r in e.get_json("/api/v1/robots")["robots"] if r["up"]}) == n and s
                ),
                30,
                message=f"shard with {sorted(names)}",
            )
            assert seen == names
