"""Configuration: YAML and flags, validated at start with errors that name the key and the value."""

from __future__ import annotations

import re
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from overseer.config import ConfigError, load_config
from overseer.config.dds import DomainConfig
from overseer.config.parsers import parse_duration
from testbed.processes import overseer_command


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "overseer.yml"
    path.write_text(text, encoding="utf-8")
    return path


def test_full_file_is_read(tmp_path: Path) -> None:
    config = load_config(
        write(
            tmp_path,
            """
web:
  listen_address: "127.0.0.1:9999"
dds:
  domains: [0, {id: 5, robot_name: forklift}]
  topics: [diagnostics_agg]
  loopback_only: true
fleet:
  stale_after: 3s
  robot_timeout: 1m
  expire_after: 2h30m
  max_robots: 50
metrics:
  value_keys: ["temperature", "volt.*"]
log_level: debug
""",
        )
    )
    assert config.web.host_and_port == ("127.0.0.1", 9999)
    assert config.dds.domains == (DomainConfig(0), DomainConfig(5, "forklift"))
    assert config.dds.domains[0].unnamespaced_robot == "domain0"
    assert config.dds.topics == ("diagnostics_agg",)
    assert (config.fleet.stale_after, config.fleet.robot_timeout, config.fleet.expire_after) == (3, 60, 9000)
    assert config.fleet.max_robots == 50
    assert config.metrics.value_key_pattern.fullmatch("voltage")
    assert not config.metrics.value_key_pattern.fullmatch("temperature_max")
    assert config.log_level == "debug"


def test_flags_override_the_file(tmp_path: Path) -> None:
    path = write(tmp_path, "fleet:\n  stale_after: 3s\n  robot_timeout: 20s\n")
    config = load_config(path, {"fleet.stale_after": 7.0, "dds.domains": [3, 4]})
    assert config.fleet.stale_after == 7.0
    assert [d.id for d in config.dds.domains] == [3, 4]


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("fleet:\n  stale_after: soon\n", "fleet.stale_after: expected a duration such as 5s, got 'soon'"),
        ("fleet:\n  stale_after: -1\n", "fleet.stale_after: must be a positive duration, got -1"),
        ("fleet:\n  max_robots: 0\n", "fleet.max_robots: expected a positive integer, got 0"),
        ("fleet:\n  robot_timeout: 1s\n", "fleet.robot_timeout: must not be shorter than fleet.stale_after"),
        ("dds:\n  domains: [300]\n", "dds.domains[0].id: expected a DDS domain id from 0 to 232, got 300"),
        ("dds:\n  domains: [1, 1]\n", "dds.domains: domain ids must be unique"),
        ("dds:\n  topics: [rosout]\n", "dds.topics: expected diagnostics_agg or diagnostics, got 'rosout'"),
        (
            "dds:\n  loopback_only: yes please\n",
            "dds.loopback_only: expected true or false, got 'yes please'",
        ),
        ("web:\n  listen_address: nowhere\n", "web.listen_address: expected host:port, got 'nowhere'"),
        ("fleet:\n  stale_afer: 5s\n", "fleet.stale_afer: unknown key"),
        ("metrics:\n  value_keys: ['(']\n", "metrics.value_keys: '(' is not a regular expression"),
        ("log_level: loud\n", "log_level: expected one of debug, info, warning, error, got 'loud'"),
        (
            "ros1:\n  robots:\n    - {name: a, master_uri: 'http://h:11311'}\n"
            "    - {name: b, master_uri: 'http://h:11311/'}\n",
            "ros1.robots: each robot needs a master of its own",
        ),
        (
            "ros1:\n  robots:\n    - {name: a, master_uri: 'ftp://h'}\n",
            "ros1.robots[0].master_uri: expected http://",
        ),
        (
            "zenoh:\n  queue_length: 0\n",
            "zenoh.queue_length: expected a number of samples from 1 to 10000000, got 0",
        ),
        ("- a list\n", "expected a mapping at the top"),
        ("fleet: [\n", "is not valid YAML"),
    ],
)
def test_bad_file_names_key_and_value(tmp_path: Path, text: str, message: str) -> None:
    with pytest.raises(ConfigError) as raised:
        load_config(write(tmp_path, text))
    assert message in str(raised.value)


def test_missing_file_is_a_config_error(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"config\.file: cannot read"):
        load_config(tmp_path / "absent.yml")


@pytest.mark.parametrize(
    ("text", "seconds"), [("5s", 5), ("250ms", 0.25), ("1h30m", 5400), (2, 2), ("1d", 86400)]
)
def test_durations(text: str | int, seconds: float) -> None:
    assert parse_duration(text, "k") == seconds


@pytest.mark.servers
def test_run_with_bad_file_exits_nonzero_with_one_line(tmp_path: Path) -> None:
    path = write(tmp_path, "fleet:\n  expire_after: never\n")
    result = subprocess.run(
        [*overseer_command(), "run", f"--config.file={path}"], capture_output=True, text=True, timeout=60
    )
    assert result.returncode == 2
    assert result.stdout == ""
    assert result.stderr.splitlines() == [
        "overseer run: configuration error: fleet.expire_after: expected a duration such as 5s, got 'never'"
    ]


@pytest.mark.servers
def test_run_with_bad_flag_value_exits_nonzero(tmp_path: Path) -> None:
    result = subprocess.run(
        [*overseer_command(), "run", "--fleet.stale-after=fast"], capture_output=True, text=True, timeout=60
    )
    assert result.returncode == 2
    assert (
        "--fleet.stale-after (fleet.stale_after): expected a duration such as 5s, got 'fast'" in result.stderr
    )


@pytest.mark.servers
def test_simulate_with_bad_event_exits_nonzero() -> None:
    result = subprocess.run(
        [*overseer_command(), "simulate", "--event=soon:robot1:stop"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 2
    assert "time 'soon' is not a number of seconds" in result.stderr


@pytest.mark.servers
def test_simulate_with_a_namespace_dds_cannot_carry_exits_nonzero() -> None:
    result = subprocess.run(
        [*overseer_command(), "simulate", '--namespace-prefix=site "a"'],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 2
    assert "--namespace-prefix: expected ROS name tokens" in result.stderr


@pytest.mark.servers
def test_run_on_a_busy_port_exits_nonzero_with_one_line(tmp_path: Path) -> None:
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        result = subprocess.run(
            [*overseer_command(), "run", f"--web.listen-address=127.0.0.1:{port}", "--dds.loopback-only"],
            capture_output=True,
            text=True,
            timeout=60,
            cwd=tmp_path,  # the exporter has opened its event database by the time the port is refused
        )
    assert result.returncode == 1
    assert result.stderr.splitlines() == [
        f"overseer run: cannot listen on 127.0.0.1:{port}: Address already in use"
    ]


def test_ingest_workers_default_to_the_cores_this_process_may_use_at_most_sixteen() -> None:
    import os

    cores = len(os.sched_getaffinity(0))
    assert load_config(None).ingest.workers == min(cores, 16)
    assert load_config(None, {"ingest.workers": "3"}).ingest.workers == 3
    assert load_config(None, {"ingest.workers": 1}).ingest.workers == 1


@pytest.mark.parametrize("value", [0, 65, -1, "two", True, 1.5, ""])
def test_bad_ingest_workers_name_the_key_and_the_range(value: object) -> None:
    with pytest.raises(ConfigError, match=r"ingest\.workers: expected a whole number from 1 to 64"):
        load_config(None, {"ingest.workers": value})


@pytest.mark.servers
def test_run_whose_dds_participant_cannot_join_exits_nonzero_naming_the_transport(tmp_path: Path) -> None:
    """A fixed participant index another participant holds (real Cyclone DDS): the exporter's cannot bind."""
    fixed_index = (
        '<CycloneDDS><Domain id="any"><General><Interfaces><NetworkInterface name="lo"/></Interfaces>'
        "<AllowMulticast>false</AllowMulticast></General><Discovery><ParticipantIndex>7</ParticipantIndex>"
        "</Discovery></Domain></CycloneDDS>"
    )
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import sys, time; from cyclonedds.domain import Domain, DomainParticipant; "
            f"d = Domain(97, {fixed_index!r}); p = DomainParticipant(97); print('joined', flush=True); "
            "sys.stdin.read()",
        ],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout is not None and holder.stdout.readline() == "joined\n"
        result = subprocess.run(
            [
                *overseer_command(),
                "run",
                f"--web.listen-address=127.0.0.1:{port}",
                "--dds.domain=97",
                f"--dds.cyclonedds-uri={fixed_index}",
                "--ingest.workers=2",
            ],
            capture_output=True,
            text=True,
            timeout=60,
            cwd=tmp_path,
        )
    finally:
        holder.kill()
        holder.wait()
    assert result.returncode == 1
    # The exporter's own participant relays the workers their robots: it names DDS and the error in one line.
    last = result.stderr.splitlines()[-1]
    assert re.fullmatch(r"overseer run: dds could not start: DDSException: .+", last), last
