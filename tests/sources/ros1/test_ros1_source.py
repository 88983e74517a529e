"""The ROS 1 source against a real ROS 1 master: rospy publishers, restarts, and a lying fake publisher.

In-process tests drive `Ros1Source` directly to see its error counts and memory; the end-to-end
tests run the exporter next to a ROS 2 robot from the simulator and read its HTTP API.
"""

from __future__ import annotations

import struct
import time
import tracemalloc
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest
import yaml

from overseer.codec.ros1 import encode_diagnostic_array
from overseer.config.ros1 import Ros1Config, Ros1Robot
from overseer.fleet.documents import robot_document
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import FleetLimits, FleetModel
from overseer.sources.ros1 import source as ros1_source
from overseer.sources.ros1.source import Ros1Source
from overseer.sources.ros1.tcpros import (
    TcprosError,
    check_publisher_header,
    decode_header,
    encode_header,
    subscriber_header,
)
from overseer.sources.ros1.xmlrpc import RosApiError, ros_call
from testbed.ports import free_port
from testbed.processes import Exporter, running_exporter, running_simulator, wait_for
from testbed.ros1 import (
    Master,
    fake_publisher,
    frame,
    kill,
    running_master,
    running_publisher,
    start_master,
    start_publisher,
)

FAST = ("--fleet.stale-after=1s", "--fleet.robot-timeout=2s")
AGGREGATOR = ("OK:/Power/Battery:Charged:bms:voltage=12.6", "WARN:/Temp/Motor:Warm:t1:temperature=71.5")
VALID = encode_diagnostic_array(
    DiagnosticArray(1, 2, "", (DiagnosticStatus(1, "/Fake/Sensor", "Warm", "f1", (("t", "70"),)),))
)


# --- the TCPROS connection header ---------------------------------------------------------------


@pytest.mark.servers
def test_connection_header_roundtrips_and_carries_what_rospy_requires() -> None:
    header = encode_header(subscriber_header("/overseer", "/diagnostics_agg"))
    (length,) = struct.unpack_from("<I", header)
    assert length == len(header) - 4
    fields = decode_header(header[4:])
    assert fields == {
        "callerid": "/overseer",
        "topic": "/diagnostics_agg",
        "md5sum": "60810da900de1dd6ddd437c3503511da",
        "type": "diagnostic_msgs/DiagnosticArray",
        "tcp_nodelay": "1",
    }


def test_value_may_contain_equals_signs() -> None:
    assert decode_header(encode_header({"message_definition": "a=b=c"})[4:]) == {
        "message_definition": "a=b=c"
    }


@pytest.mark.parametrize(
    "block",
    [b"\x05\x00\x00\x00ab=c", b"\x03\x00", b"\x03\x00\x00\x00abc"],
    ids=["field runs past the end", "truncated length", "no equals sign"],
)
def test_malformed_connection_header_is_a_handshake_error(block: bytes) -> None:
    with pytest.raises(TcprosError) as raised:
        decode_header(block)
    assert raised.value.reason == "handshake_error"


@pytest.mark.parametrize(
    "fields",
    [{"error": "no such topic"}, {"md5sum": "0" * 32}, {}],
    ids=["refused", "other type", "no md5sum"],
)
def test_publisher_header_that_is_not_diagnostic_array_is_refused(fields: dict[str, str]) -> None:
    with pytest.raises(TcprosError, match=r"refused|md5sum"):
        check_publisher_header(fields)


def test_publisher_header_with_wildcard_md5sum_is_accepted() -> None:
    check_publisher_header({"md5sum": "*"})


@pytest.mark.parametrize("uri", ["http://a..b:11311", f"http://127.0.0.1:{free_port()}"])
def test_unreachable_or_unresolvable_peer_is_an_unreachable_api_error(uri: str) -> None:
    with pytest.raises(RosApiError, match="unreachable") as raised:
        ros_call(uri, "getPid", "/test", timeout=2)
    assert raised.value.unreachable


# --- the source in process --------------------------------------------------------------------


@contextmanager
def running_source(*robots: tuple[str, str], **config: Any) -> Iterator[tuple[Ros1Source, FleetModel]]:
    """A started Ros1Source on fast timings, always stopped."""
    model = FleetModel(FleetLimits(stale_after=1, robot_timeout=2))
    settings = {"reconnect_min": 0.1, "reconnect_max": 1.0, "poll_interval": 1.0, **config}
    source = Ros1Source(Ros1Config(robots=tuple(Ros1Robot(n, uri) for n, uri in robots), **settings), model)
    source.start()
    try:
        yield source, model
    finally:
        source.stop()


def robot_view(model: FleetModel, name: str) -> dict[str, Any]:
    """Whether the robot is up, its transport, and its components' current states by name."""
    snapshot = model.snapshot()
    robot = snapshot.find(name)
    assert robot is not None
    document = robot_document(snapshot, robot)
    return {"up": document["up"], "transport": document["transport"], "states": states(document)}


@pytest.mark.servers
def test_source_feeds_rospy_diagnostics_into_the_model(tmp_path: Path) -> None:
    with (
        running_master(tmp_path) as master,
        running_publisher(tmp_path, master, "aggregator", AGGREGATOR),
        running_source(("r1", master.uri)) as (_, model),
    ):
        wait_for(lambda: robot_view(model, "r1")["up"], 20, message="r1 up")
        view = robot_view(model, "r1")
        assert view["transport"] == "ros1"
        assert view["states"] == {"/Power/Battery": "OK", "/Temp/Motor": "WARN"}
        snapshot = model.snapshot()
        robot = snapshot.find("r1")
        assert robot is not None
        motor = next(c for c in robot_document(snapshot, robot)["components"] if c["name"] == "/Temp/Motor")
        assert (motor["hardware_id"], motor["message"], motor["values"]) == (
            "t1",
            "Warm",
            [{"key": "temperature", "value": "71.5"}],
        )


@pytest.mark.servers
def test_repeated_identical_messages_keep_the_robot_fresh(tmp_path: Path) -> None:
    with (
        running_master(tmp_path) as master,
        running_publisher(tmp_path, master, "aggregator", AGGREGATOR, rate=5),
        running_source(("r1", master.uri)) as (_, model),
    ):
        wait_for(lambda: robot_view(model, "r1")["up"], 20, message="r1 up")
        time.sleep(2.5)  # past robot_timeout and stale_after: only the later, unchanged messages count
        assert robot_view(model, "r1")["states"] == {"/Power/Battery": "OK", "/Temp/Motor": "WARN"}
        assert model.snapshot().message_counts[("ros1", "received")] >= 10


@pytest.mark.servers
def test_robot_is_known_and_down_before_its_first_message(tmp_path: Path) -> None:
    with running_master(tmp_path) as master, running_source(("r1", master.uri)) as (_, model):
        assert robot_view(model, "r1") == {"up": False, "transport": "ros1", "states": {}}


@pytest.mark.servers
def test_source_registers_with_the_master_and_unregisters_on_stop(tmp_path: Path) -> None:
    with running_master(tmp_path) as master:
        with running_source(("r1", master.uri), caller_id="/overseer_test") as (source, _):
            wait_for(lambda: "/overseer_test" in master.subscribers(), 10, message="registration")
            started = time.monotonic()
            source.stop()
            stop_seconds = time.monotonic() - started
        assert master.subscribers() == []
        assert stop_seconds < 3


@pytest.mark.servers
def test_unreachable_master_is_counted_retried_and_followed_once_it_starts(tmp_path: Path) -> None:
    port = free_port()
    with running_source(("r1", f"http://127.0.0.1:{port}")) as (source, model):
        wait_for(lambda: source.error_counts().get("master_unreachable", 0) >= 3, 10, message="retries")
        assert not robot_view(model, "r1")["up"]
        with (
            running_master(tmp_path, port) as master,
            running_publisher(tmp_path, master, "aggregator", AGGREGATOR),
        ):
            wait_for(lambda: robot_view(model, "r1")["up"], 20, message="r1 up after its master started")


@pytest.mark.servers
def test_slave_api_answers_the_master_and_tools(tmp_path: Path) -> None:
    with running_master(tmp_path) as master, running_source(("r1", master.uri)) as (source, _):
        wait_for(lambda: "/overseer" in master.subscribers(), 10, message="registration")
        api = ros_call(master.uri, "lookupNode", "/test", "/overseer", timeout=5)
        assert ros_call(api, "getMasterUri", "/test", timeout=5) == master.uri
        assert ros_call(api, "getSubscriptions", "/test", timeout=5) == [
            ["/diagnostics_agg", "diagnostic_msgs/DiagnosticArray"]
        ]
        assert ros_call(api, "getPublications", "/test", timeout=5) == []
        assert isinstance(ros_call(api, "getPid", "/test", timeout=5), int)
        assert ros_call(api, "getBusInfo", "/test", timeout=5) == []
        assert ros_call(api, "paramUpdate", "/test", "/p", 1, timeout=5) == 0
        with pytest.raises(RosApiError, match="publishes nothing"):
            ros_call(api, "requestTopic", "/test", "/diagnostics_agg", [["TCPROS"]], timeout=5)
        with pytest.raises(RosApiError, match="not a subscriber"):
            ros_call(api, "publisherUpdate", "/master", "/other", [], timeout=5)
        ros_call(api, "shutdown", "/test", "testing", timeout=5)
        assert source.error_counts()["shutdown_requested"] == 1
        assert "/overseer" in master.subscribers()


@pytest.mark.servers
def test_publisher_update_from_the_master_is_followed_between_polls(tmp_path: Path) -> None:
    with (
        running_master(tmp_path) as master,
        running_source(("r1", master.uri), poll_interval=3600.0) as (_, model),
    ):
        wait_for(lambda: "/overseer" in master.subscribers(), 10, message="registration")
        with running_publisher(tmp_path, master, "aggregator", AGGREGATOR):
            wait_for(lambda: robot_view(model, "r1")["up"], 20, message="r1 up without polling")


def lying_script(connection: int) -> list[bytes]:
    """A valid frame, then a length prefix over the cap, then one under it with little behind it."""
    if connection == 1:
        return [frame(VALID), struct.pack("<I", 0xFFFFFFF0) + b"\x00" * 16]
    if connection == 2:
        return [frame(VALID), struct.pack("<I", 15 * 1024 * 1024) + b"x" * 1000]
    return [frame(VALID)] * 20


@pytest.mark.servers
def test_fake_publisher_lying_length_prefix_allocates_nothing_and_is_retried(tmp_path: Path) -> None:
    with running_master(tmp_path) as master:
        tracemalloc.start()
        try:
            with (
                fake_publisher(master, lying_script) as fake,
                running_source(("r1", master.uri)) as (source, model),
            ):
                wait_for(lambda: fake.connections >= 3, 20, message="a third connection")
                wait_for(lambda: robot_view(model, "r1")["up"], 10, message="r1 up on the third connection")
                assert robot_view(model, "r1")["states"] == {"/Fake/Sensor": "WARN"}
                _, peak = tracemalloc.get_traced_memory()
                counts = source.error_counts()
        finally:
            tracemalloc.stop()
    assert counts["frame_too_large"] == 1
    assert counts["connection_lost"] >= 1
    assert peak < 4 * 1024 * 1024


@pytest.mark.servers
def test_fake_publisher_garbled_frame_is_a_counted_decode_error_then_a_reconnect(tmp_path: Path) -> None:
    with (
        running_master(tmp_path) as master,
        fake_publisher(master, lambda n: [frame(VALID), frame(b"garbage" * 3), frame(VALID)]) as fake,
        running_source(("r1", master.uri)) as (source, model),
    ):
        wait_for(lambda: fake.connections >= 3, 20, message="reconnections")
        counts = model.snapshot().message_counts
        assert counts[("ros1", "decode_error")] >= 2
        assert counts[("ros1", "received")] >= 2
        assert "decode_error" not in source.error_counts()


@pytest.mark.servers
def test_fake_publisher_silent_past_the_idle_timeout_is_dropped_and_reconnected(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(ros1_source, "MIN_IDLE_TIMEOUT_SECONDS", 0.5)
    monkeypatch.setattr(ros1_source, "IDLE_TIMEOUT_ROBOT_TIMEOUTS", 0)
    with (
        running_master(tmp_path) as master,
        fake_publisher(master, lambda n: [frame(VALID)], hold_open=True) as fake,
        running_source(("r1", master.uri)) as (source, _),
    ):
        wait_for(lambda: fake.connections >= 2, 10, message="a reconnection after silence")
        assert source.error_counts()["idle_timeout"] >= 1


@pytest.mark.servers
def test_fake_publisher_silent_for_longer_than_robot_timeout_keeps_its_connection(tmp_path: Path) -> None:
    with (
        running_master(tmp_path) as master,
        # Its period learned first (0.3 s), so that robot_timeout (2 s) is its bound, not three stale_after.
        fake_publisher(
            master,
            lambda n: [frame(VALID), 0.3, frame(VALID), 0.3, frame(VALID), 3.0, frame(VALID)],
            hold_open=True,
        ) as fake,
        running_source(("r1", master.uri)) as (source, model),
    ):
        wait_for(lambda: robot_view(model, "r1")["up"], 10, message="r1 up")
        wait_for(lambda: not robot_view(model, "r1")["up"], 10, message="r1 down while silent")
        wait_for(lambda: robot_view(model, "r1")["up"], 10, message="r1 up again")
        assert fake.connections == 1
        assert source.error_counts() == {}


@pytest.mark.servers
def test_fake_publisher_of_another_type_is_a_handshake_error(tmp_path: Path) -> None:
    with (
        running_master(tmp_path) as master,
        fake_publisher(master, lambda n: [frame(VALID)], reply_header={"md5sum": "0" * 32}) as fake,
        running_source(("r1", master.uri)) as (source, model),
    ):
        wait_for(
            lambda: source.error_counts().get("handshake_error", 0) >= 2, 20, message="refused handshakes"
        )
        assert fake.subscriber_headers[0]["md5sum"] == "60810da900de1dd6ddd437c3503511da"
        assert not robot_view(model, "r1")["up"]


# --- the exporter, end to end -----------------------------------------------------------------


def states(robot: dict[str, Any]) -> dict[str, str]:
    return {c["name"]: c["state"] for c in robot["components"]}


def robot_up(exporter: Exporter, name: str) -> dict[str, Any] | None:
    robot = exporter.robot(name)
    return robot if robot and robot["up"] else None


def robot_down(exporter: Exporter, name: str) -> dict[str, Any] | None:
    robot = exporter.robot(name)
    return robot if robot and not robot["up"] else None


@pytest.mark.servers
def test_exporter_shows_two_ros1_robots_next_to_a_ros2_robot_from_one_config_file(
    tmp_path: Path, dds_domain: int
) -> None:
    with running_master(tmp_path) as master_a, running_master(tmp_path) as master_b:
        config = tmp_path / "overseer.yml"
        config.write_text(
            yaml.safe_dump(
                {
                    "dds": {"domains": [dds_domain]},
                    "ros1": {
                        "robots": [
                            {"name": "ros1a", "master_uri": master_a.uri.rstrip("/")},
                            {
                                "name": "ros1b",
                                "master_uri": master_b.uri.rstrip("/"),
                                "topic": "diagnostics_agg",
                            },
                        ]
                    },
                    "fleet": {"stale_after": "1s", "robot_timeout": "2s"},
                }
            ),
            encoding="utf-8",
        )
        with (
            running_publisher(tmp_path, master_a, "aggregator", AGGREGATOR),
            running_publisher(
                tmp_path, master_b, "aggregator", ("ERROR:/Laser:No scans:hokuyo", "OK:/Power:ok")
            ),
            running_exporter(tmp_path, None, f"--config.file={config}") as exporter,
            running_simulator(tmp_path, dds_domain, "--robots=1"),
        ):
            ros1a = wait_for(lambda: robot_up(exporter, "ros1a"), 30, message="ros1a up")
            ros1b = wait_for(lambda: robot_up(exporter, "ros1b"), 30, message="ros1b up")
            robot1 = wait_for(lambda: robot_up(exporter, "robot1"), 30, message="the ROS 2 robot up")
            assert (ros1a["transport"], ros1a["state"], states(ros1a)) == (
                "ros1",
                "WARN",
                {"/Power/Battery": "OK", "/Temp/Motor": "WARN"},
            )
            assert (ros1b["transport"], ros1b["state"], states(ros1b)) == (
                "ros1",
                "ERROR",
                {"/Laser": "ERROR", "/Power": "OK"},
            )
            assert robot1["transport"] == "dds"
            samples = exporter.samples()
            for name in ("ros1a", "ros1b", "robot1"):
                assert samples["ros_diagnostics_robot_up"][(("robot", name),)] == 1
            assert samples["ros_diagnostics_robot_level"][(("robot", "ros1b"),)] == 2
            laser = (("component", "/Laser"), ("hardware_id", "hokuyo"), ("robot", "ros1b"))
            assert samples["ros_diagnostics_level"][laser] == 2
            temperature = (
                ("component", "/Temp/Motor"),
                ("hardware_id", "t1"),
                ("key", "temperature"),
                ("robot", "ros1a"),
            )
            assert samples["ros_diagnostics_value"][temperature] == 71.5
            assert samples["overseer_messages_total"][(("result", "received"), ("transport", "ros1"))] >= 2


@pytest.mark.servers
def test_killed_publisher_goes_stale_and_comes_back_without_restarting_the_exporter(
    tmp_path: Path, dds_domain: int
) -> None:
    with running_master(tmp_path) as master:
        publisher = start_publisher(tmp_path, master, "aggregator", AGGREGATOR)
        try:
            with running_exporter(
                tmp_path, dds_domain, f"--ros1.robot=ros1a={master.uri.rstrip('/')}", *FAST
            ) as exporter:
                wait_for(lambda: robot_up(exporter, "ros1a"), 30, message="ros1a up")
                kill(publisher)
                down = wait_for(lambda: robot_down(exporter, "ros1a"), 10, message="ros1a down")
                assert down["state"] == "STALE"
                assert set(states(down).values()) == {"STALE"}
                restarted = time.monotonic()
                publisher = start_publisher(tmp_path, master, "aggregator", AGGREGATOR)
                back = wait_for(lambda: robot_up(exporter, "ros1a"), 30, interval=0.05, message="ros1a back")
                print(f"publisher registered to robot up: {time.monotonic() - restarted:.2f} s")
                assert states(back) == {"/Power/Battery": "OK", "/Temp/Motor": "WARN"}
        finally:
            publisher.stop()


@pytest.mark.servers
def test_master_restart_is_recovered(tmp_path: Path, dds_domain: int) -> None:
    port = free_port()
    master: Master = start_master(tmp_path, port)
    publisher = start_publisher(tmp_path, master, "aggregator", AGGREGATOR)
    try:
        with running_exporter(
            tmp_path, dds_domain, f"--ros1.robot=ros1a=http://127.0.0.1:{port}", *FAST
        ) as exporter:
            wait_for(lambda: robot_up(exporter, "ros1a"), 30, message="ros1a up")

            # The master alone restarts: the publisher's connection carries on, and we register again.
            kill(master)
            time.sleep(3)
            assert robot_up(exporter, "ros1a"), "messages flow without the master"
            master = start_master(tmp_path, port)
            restarted = time.monotonic()
            wait_for(
                lambda: "/overseer" in master.subscribers(), 40, interval=0.05, message="registered again"
            )
            print(f"master restarted to registered again: {time.monotonic() - restarted:.2f} s")

            # The whole robot restarts: master and publisher die, and come back.
            kill(publisher)
            kill(master)
            wait_for(lambda: robot_down(exporter, "ros1a"), 10, message="ros1a down")
            master = start_master(tmp_path, port)
            publisher = start_publisher(tmp_path, master, "aggregator", AGGREGATOR)
            restarted = time.monotonic()
            wait_for(lambda: robot_up(exporter, "ros1a"), 40, interval=0.05, message="ros1a back")
            print(f"robot restarted (master and publisher) to robot up: {time.monotonic() - restarted:.2f} s")
    finally:
        publisher.stop()
        master.stop()


@pytest.mark.servers
def test_fake_publisher_garbled_and_lying_frames_are_counted_and_the_exporter_keeps_serving(
    tmp_path: Path, dds_domain: int
) -> None:
    def script(connection: int) -> list[bytes]:
        lie = struct.pack("<I", 0xFFFFFFF0) if connection % 2 else frame(b"\xff" * 40)
        return [frame(VALID), lie]

    with (
        running_master(tmp_path) as master,
        fake_publisher(master, script) as fake,
        running_exporter(
            tmp_path, dds_domain, f"--ros1.robot=fake={master.uri.rstrip('/')}", *FAST
        ) as exporter,
        running_simulator(tmp_path, dds_domain, "--robots=1"),
    ):
        wait_for(lambda: fake.connections >= 4, 30, message="reconnections")
        decode_errors = ("overseer_messages_total", (("result", "decode_error"), ("transport", "ros1")))
        wait_for(
            lambda: exporter.samples()[decode_errors[0]][decode_errors[1]] >= 1, 10, message="decode errors"
        )
        assert exporter.get("/-/healthy")
        fake_robot = wait_for(lambda: robot_up(exporter, "fake"), 10, message="the fake robot up")
        assert states(fake_robot) == {"/Fake/Sensor": "WARN"}
        wait_for(lambda: robot_up(exporter, "robot1"), 30, message="the ROS 2 robot up")
    assert exporter.process.returncode == 0, exporter.log()
