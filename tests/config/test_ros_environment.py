"""ROS's environment variables set the ROS 2 transports' defaults, as every ROS 2 node reads them.

A flag or the configuration file wins over the environment; the start-up log says where each value
came from. The last test runs a real exporter and simulator on a DDS domain given only by ROS_DOMAIN_ID.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from overseer.config import ConfigError, load_config
from overseer.config.loading import ros_settings
from overseer.config.ros_environment import Origin
from testbed.processes import running_exporter, running_simulator, wait_for


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "overseer.yml"
    path.write_text(text, encoding="utf-8")
    return path


def origin(config_origins: tuple[Origin, ...], key: str) -> str:
    return next(item.source for item in config_origins if item.key == key)


def test_ros_domain_id_is_the_dds_domain_when_nothing_else_says() -> None:
    config = load_config(None, environ={"ROS_DOMAIN_ID": "7"})
    assert [domain.id for domain in config.dds.domains] == [7]
    assert origin(config.origins, "dds.domains") == "ROS_DOMAIN_ID=7"
    assert "dds.domains 7 (ROS_DOMAIN_ID=7)" in ros_settings(config)


def test_a_flag_and_the_file_win_over_the_environment(tmp_path: Path) -> None:
    flagged = load_config(None, {"dds.domains": [3]}, environ={"ROS_DOMAIN_ID": "7"})
    assert [domain.id for domain in flagged.dds.domains] == [3]
    assert origin(flagged.origins, "dds.domains") == "flag"
    filed = load_config(write(tmp_path, "dds:\n  domains: [4]\n"), environ={"ROS_DOMAIN_ID": "7"})
    assert [domain.id for domain in filed.dds.domains] == [4]
    assert origin(filed.origins, "dds.domains") == "config file"
    assert origin(load_config(None, environ={}).origins, "dds.domains") == "default"


def test_the_zenoh_domain_follows_ros_domain_id_but_the_environment_never_turns_zenoh_on() -> None:
    config = load_config(None, {"zenoh.connect": ["tcp/127.0.0.1:7447"]}, environ={"ROS_DOMAIN_ID": "12"})
    assert config.zenoh.enabled and config.zenoh.domain == 12
    assert "zenoh.domain 12 (ROS_DOMAIN_ID=12)" in ros_settings(config)
    assert not load_config(None, environ={"ROS_DOMAIN_ID": "12"}).zenoh.enabled


@pytest.mark.parametrize(
    ("environ", "loopback", "source"),
    [
        ({"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}, True, "ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST"),
        ({"ROS_AUTOMATIC_DISCOVERY_RANGE": "off"}, True, "ROS_AUTOMATIC_DISCOVERY_RANGE=OFF"),
        ({"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"}, False, "default"),
        ({"ROS_LOCALHOST_ONLY": "1"}, True, "ROS_LOCALHOST_ONLY=1"),
        ({"ROS_LOCALHOST_ONLY": "0"}, False, "default"),
        # The newer variable says what the older one meant, as in ROS 2 Jazzy.
        ({"ROS_LOCALHOST_ONLY": "1", "ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"}, False, "default"),
    ],
)
def test_the_discovery_range_keeps_dds_on_loopback(
    environ: dict[str, str], loopback: bool, source: str
) -> None:
    config = load_config(None, environ=environ)
    assert config.dds.loopback_only is loopback
    assert origin(config.origins, "dds.loopback_only") == source


def test_static_peers_are_dds_peers() -> None:
    config = load_config(None, environ={"ROS_STATIC_PEERS": "10.0.0.5; robot7.site-a.example;;"})
    assert [str(peer) for peer in config.dds.peers] == ["10.0.0.5", "robot7.site-a.example"]
    assert origin(config.origins, "dds.peers") == "ROS_STATIC_PEERS=10.0.0.5;robot7.site-a.example"
    local = load_config(
        None, environ={"ROS_STATIC_PEERS": "127.0.0.1", "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    )
    assert local.dds.loopback_only and [str(peer) for peer in local.dds.peers] == ["127.0.0.1"]


@pytest.mark.parametrize(
    ("environ", "message"),
    [
        ({"ROS_DOMAIN_ID": "ten"}, "ROS_DOMAIN_ID: expected a domain id from 0 to 232, got 'ten'"),
        ({"ROS_DOMAIN_ID": "233"}, "ROS_DOMAIN_ID: expected a domain id from 0 to 232, got '233'"),
        (
            {"ROS_AUTOMATIC_DISCOVERY_RANGE": "EVERYWHERE"},
            "ROS_AUTOMATIC_DISCOVERY_RANGE: expected one of SUBNET, LOCALHOST, OFF, SYSTEM_DEFAULT, "
            "got 'EVERYWHERE'",
        ),
        ({"ROS_STATIC_PEERS": "not a host!"}, "ROS_STATIC_PEERS[0]: expected HOST or HOST:PORT"),
        (
            {"ROS_STATIC_PEERS": "10.0.0.5", "ROS_LOCALHOST_ONLY": "1"},
            "ROS_STATIC_PEERS: '10.0.0.5' is not on this host, but ROS_LOCALHOST_ONLY=1 keeps discovery "
            "on it",
        ),
    ],
)
def test_a_bad_variable_is_one_error_naming_it(environ: dict[str, str], message: str) -> None:
    with pytest.raises(ConfigError) as raised:
        load_config(None, environ=environ)
    assert message in str(raised.value)


@pytest.mark.servers
def test_an_exporter_started_with_ros_domain_id_alone_hears_that_domain(
    tmp_path: Path, dds_domain: int
) -> None:
    environ = {"ROS_DOMAIN_ID": str(dds_domain), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    with (
        running_exporter(tmp_path, None, "--ingest.workers=1", env=environ, loopback_flag=False) as exporter,
        running_simulator(tmp_path, dds_domain, "--robots=1", "--namespace-prefix=rosenv"),
    ):
        wait_for(lambda: exporter.get_json("/api/v1/robots")["robots"], 30, message="the robot")
        robots = [robot["robot"] for robot in exporter.get_json("/api/v1/robots")["robots"]]
    assert robots == ["rosenv1"]
    log = exporter.log()
    assert f"dds.domains {dds_domain} (ROS_DOMAIN_ID={dds_domain})" in log
    assert "dds.loopback_only true (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST)" in log


def test_ros2_turns_the_dds_source_off_unless_the_file_turns_it_on(tmp_path: Path) -> None:
    config = load_config(None, {"ros2.enabled": True}, environ={"ROS_DOMAIN_ID": "5"})
    assert config.ros2.enabled and not config.dds.enabled and config.ros2.domain == 5
    both = load_config(
        write(tmp_path, "dds:\n  enabled: true\n  domains: [1]\nros2:\n  domain: 2\n"), environ={}
    )
    assert both.dds.enabled and both.ros2.enabled
    with pytest.raises(ConfigError) as raised:
        load_config(write(tmp_path, "dds:\n  enabled: true\nros2:\n  enabled: true\n"), environ={})
    assert "the DDS source and the ROS 2 node would both follow domain 0's robots" in str(raised.value)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("ros2:\n  node_name: 'over seer'\n", "ros2.node_name: expected a ROS node name"),
        ("ros2:\n  fleet_topic: fleet\n", "ros2.fleet_topic: expected a topic name such as /overseer/fleet"),
        ("ros2:\n  topics: [rosout]\n", "ros2.topics: expected diagnostics_agg or diagnostics, got 'rosout'"),
        ("ros2:\n  domain: 300\n", "ros2.domain: expected a ROS domain id from 0 to 232, got 300"),
        ("ros2:\n  fleet_period: soon\n", "ros2.fleet_period: expected a duration such as 5s, got 'soon'"),
    ],
)
def test_bad_ros2_settings_name_key_and_value(tmp_path: Path, text: str, message: str) -> None:
    with pytest.raises(ConfigError) as raised:
        load_config(write(tmp_path, text), environ={})
    assert message in str(raised.value)
