"""Configuration for alerts that say what is wrong: message labels, the external URL, ROS masters by URL."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from overseer.cli import COMMANDS, parser_of
from overseer.config import Config, ConfigError, load_config
from overseer.config.loading import ALL_OPTIONS
from overseer.config.options import overrides
from overseer.config.ros1 import Ros1Robot
from overseer.ros_master import master_host
from testbed.processes import overseer_command


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "overseer.yml"
    path.write_text(text, encoding="utf-8")
    return path


def run_flags(*flags: str) -> Config:
    """The configuration `overseer run FLAGS` would start with."""
    return load_config(None, overrides(parser_of(COMMANDS).parse_args(["run", *flags]), ALL_OPTIONS))


def test_defaults_label_the_messages_of_problems_cut_to_100_characters_and_link_nowhere() -> None:
    config = load_config(None)
    assert (config.metrics.message_labels, config.metrics.message_label_length) == ("problems", 100)
    assert config.web.external_url is None
    assert config.metrics.level_changes is True


def test_file_sets_message_labels_and_external_url(tmp_path: Path) -> None:
    text = (
        "web:\n  external_url: https://ops.example/overseer/\n"
        "metrics:\n  message_labels: all\n  message_label_length: 40\n  value_keys: [voltage]\n"
        "  level_changes: false\n"
    )
    config = load_config(write(tmp_path, text))
    assert config.web.external_url == "https://ops.example/overseer"
    assert (config.metrics.message_labels, config.metrics.message_label_length) == ("all", 40)
    assert config.metrics.value_keys == ("voltage",)
    assert config.metrics.level_changes is False


def test_external_url_flag_overrides_the_file(tmp_path: Path) -> None:
    path = write(tmp_path, "web:\n  external_url: http://a:9849\n")
    args = parser_of(COMMANDS).parse_args(["run", "--web.external-url=http://b:9849/"])
    assert load_config(path, overrides(args, ALL_OPTIONS)).web.external_url == "http://b:9849"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            "metrics:\n  message_labels: some\n",
            "metrics.message_labels: expected one of none, problems, all, got 'some'",
        ),
        (
            "metrics:\n  message_label_length: 0\n",
            "metrics.message_label_length: expected an integer from 1 to 1024, got 0",
        ),
        (
            "metrics:\n  message_label_length: '20'\n",  # quoted in YAML: a string, whatever it spells
            "metrics.message_label_length: expected an integer from 1 to 1024, got '20'",
        ),
        ("metrics:\n  level_changes: 'no'\n", "metrics.level_changes: expected true or false, got 'no'"),
        (
            "web:\n  external_url: ops.example\n",
            "web.external_url: expected http(s)://HOST[:PORT][/PATH], got 'ops.example'",
        ),
        (
            "web:\n  external_url: 'http://ops.example/?robot=x'\n",
            "web.external_url: expected http(s)://HOST[:PORT][/PATH], got 'http://ops.example/?robot=x'",
        ),
    ],
)
def test_bad_values_name_key_and_value(tmp_path: Path, text: str, message: str) -> None:
    with pytest.raises(ConfigError) as raised:
        load_config(write(tmp_path, text))
    assert message in str(raised.value)


@pytest.mark.parametrize(
    ("uri", "host"),
    [
        ("http://10.0.0.5:11311", "10.0.0.5"),
        ("http://10.0.0.5:11311/", "10.0.0.5"),
        ("http://forklift-3.site-a.example:11311", "forklift-3.site-a.example"),
        ("http://Robot7", "Robot7"),
        ("https://[fd00::5]:11311", "fd00::5"),
    ],
)
def test_robot_of_a_master_is_named_after_its_host(uri: str, host: str) -> None:
    assert master_host(uri) == host
    if "[" not in uri:  # the ROS 1 source takes IPv4 addresses and host names only
        assert run_flags(f"--ros-master={uri}").ros1.robots == (Ros1Robot(host, uri),)


def test_ros_master_is_repeatable_and_mixes_with_named_robots() -> None:
    config = run_flags(
        "--ros-master=http://10.0.0.5:11311",
        "--ros-master=http://10.0.0.6:11311",
        "--ros1.robot=arm=http://10.0.0.7:11311",
    )
    assert [(robot.name, robot.master_uri) for robot in config.ros1.robots] == [
        ("arm", "http://10.0.0.7:11311"),
        ("10.0.0.5", "http://10.0.0.5:11311"),
        ("10.0.0.6", "http://10.0.0.6:11311"),
    ]


def test_a_bare_ros1_robot_name_names_the_one_master() -> None:
    config = run_flags("--ros-master=http://10.0.0.5:11311", "--ros1.robot=forklift")
    assert config.ros1.robots == (Ros1Robot("forklift", "http://10.0.0.5:11311"),)


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--ros1.robot=forklift"], "--ros1.robot: expected NAME=MASTER_URI (or NAME with exactly one"),
        (
            ["--ros-master=http://a:11311", "--ros-master=http://b:11311", "--ros1.robot=forklift"],
            "--ros1.robot: expected NAME=MASTER_URI (or NAME with exactly one",
        ),
        (
            ["--ros-master=http://a:11311", "--ros1.robot=x", "--ros1.robot=y"],
            "--ros1.robot: one name for the one --ros-master, got ['x', 'y']",
        ),
        (["--ros-master=10.0.0.5:11311"], "ros1.robots[0].master_uri: expected http://HOST:PORT"),
        (
            ["--ros-master=http://h:11311", "--ros-master=http://h:11312"],
            "ros1.robots: robot names must be unique, got ['h', 'h']",
        ),
    ],
)
def test_bad_ros_master_flags_are_config_errors(flags: list[str], message: str) -> None:
    with pytest.raises(ConfigError) as raised:
        run_flags(*flags)
    assert message in str(raised.value)


def test_robot_in_the_file_may_leave_out_its_name(tmp_path: Path) -> None:
    config = load_config(write(tmp_path, "ros1:\n  robots:\n    - {master_uri: 'http://10.0.0.5:11311'}\n"))
    assert config.ros1.robots == (Ros1Robot("10.0.0.5", "http://10.0.0.5:11311"),)


@pytest.mark.servers
def test_run_with_a_bad_external_url_exits_2_with_one_line() -> None:
    result = subprocess.run(
        [*overseer_command(), "run", "--web.external-url=overseer:9849"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 2
    assert result.stderr.splitlines() == [
        "overseer run: configuration error: --web.external-url (web.external_url): "
        "expected http(s)://HOST[:PORT][/PATH], got 'overseer:9849'"
    ]
