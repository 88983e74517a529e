"""The Zenoh transport end to end: a real router, exporter and robots, each in a process of its own.

Robots are `overseer simulate --transport zenoh`, publishing exactly as rmw_zenoh does (key with type
and hash, attachment, liveliness tokens) or as zenoh-bridge-ros2dds does. Everything is on loopback,
with Zenoh's multicast scouting off, and each test has a router of its own.
"""

from __future__ import annotations

import signal
import time
from pathlib import Path
from typing import Any

import pytest
import xxhash
import zenoh
from zenoh.ext import Int64, UInt8, z_deserialize

from overseer.codec.cdr import encode_diagnostic_array
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.simulator.zenoh_publisher import attachment
from overseer.sources.zenoh.keys import (
    DIAGNOSTIC_ARRAY_HASH,
    DIAGNOSTIC_ARRAY_TYPE,
    data_key,
    publisher_gid,
    publisher_token,
)
from testbed.nagios import run_check
from testbed.ports import free_port
from testbed.processes import Exporter, running_exporter, running_simulator, wait_for
from testbed.zenoh import (
    client_session,
    endpoint,
    exporter_args,
    running_router,
    simulator_args,
    start_router,
)

pytestmark = pytest.mark.servers  # every test here starts real servers or middleware

LEVELS = {"OK": 0, "WARN": 1, "ERROR": 2, "STALE": 3}


def metric(exporter: Exporter, name: str, **labels: str) -> float | None:
    """The value of one sample of /metrics, or None when it is absent."""
    for sample_labels, value in exporter.samples().get(name, {}).items():
        if all(dict(sample_labels).get(k) == v for k, v in labels.items()):
            return value
    return None


def robot_up(exporter: Exporter, robot: str) -> float | None:
    """`ros_diagnostics_robot_up` of `robot` (None while unknown)."""
    return metric(exporter, "ros_diagnostics_robot_up", robot=robot)


def robot_events(exporter: Exporter, robot: str, kind: str) -> list[dict[str, Any]]:
    """The robot's events of one kind in the exporter's history, newest first."""
    events: list[dict[str, Any]] = exporter.get_json(f"/api/v1/events?robot={robot}")["events"]
    return [event for event in events if event["kind"] == kind]


def wait_until_heard(
    exporter: Exporter, robot: str, components: int, timeout: float = 30
) -> dict[str, object]:
    """Wait until the API shows `robot` up with `components` components; return its document."""

    def heard() -> dict[str, object] | None:
        document = exporter.robot(robot)
        if document is not None and document["up"] and len(document["components"]) == components:
            return document
        return None

    result: dict[str, object] = wait_for(heard, timeout, message=f"{robot} heard over Zenoh")
    return result


def test_rmw_zenoh_robots_are_heard_with_their_levels_and_nested_namespaces(tmp_path: Path) -> None:
    with (
        running_router(tmp_path) as port,
        running_exporter(tmp_path, None, *exporter_args(port)) as exporter,
        running_simulator(
            tmp_path,
            0,
            *simulator_args(port, "--robots=2", "--components=5", "--namespace-prefix=site_a/robot"),
        ),
    ):
        # 5 leaves (1 ERROR, 1 WARN) and the 5 group statuses the aggregator adds.
        document = wait_until_heard(exporter, "site_a/robot1", 10)
        wait_until_heard(exporter, "site_a/robot2", 10)
        assert document["transport"] == "zenoh"
        assert document["level"] == LEVELS["ERROR"]
        levels = {c["name"]: c["level"] for c in document["components"]}  # type: ignore[attr-defined]
        assert levels["/Laser/Laser1"] == LEVELS["ERROR"] and levels["/Camera/Cam1"] == LEVELS["WARN"]
        assert levels["/Power/Robot Battery"] == LEVELS["OK"]
        listed = {r["robot"]: r for r in exporter.get_json("/api/v1/robots")["robots"]}
        assert set(listed) == {"site_a/robot1", "site_a/robot2"}
        assert metric(exporter, "ros_diagnostics_robot_level", robot="site_a/robot2") == LEVELS["ERROR"]
        assert (
            metric(
                exporter,
                "ros_diagnostics_level",
                robot="site_a/robot1",
                component="/Camera/Cam1",
                hardware_id="camera1",
            )
            == LEVELS["WARN"]
        )
        assert robot_up(exporter, "site_a/robot1") == 1.0
        assert metric(exporter, "overseer_messages_total", transport="zenoh", result="received")
        assert metric(exporter, "overseer_source_errors_total", reason="type_hash_mismatch") is None


def test_robots_behind_zenoh_bridge_ros2dds_are_heard_and_down_when_their_bridge_goes(tmp_path: Path) -> None:
    port = free_port()
    bridged = simulator_args(port, "--zenoh.bridge-keys", "--robots=1", "--namespace-prefix=fleet/amr")
    with (
        running_router(tmp_path, port),
        running_exporter(tmp_path, None, *exporter_args(port, "--fleet.robot-timeout=60s")) as exporter,
        running_simulator(tmp_path, 0, *bridged) as bridge,
    ):
        document = wait_until_heard(exporter, "fleet/amr1", 15)
        assert document["level"] == LEVELS["ERROR"] and document["transport"] == "zenoh"
        assert robot_up(exporter, "fleet/amr1") == 1.0
        bridge.process.send_signal(signal.SIGKILL)
        wait_for(
            lambda: robot_up(exporter, "fleet/amr1") == 0.0, 5, interval=0.1, message="bridged robot down"
        )


def test_a_router_that_comes_up_later_is_joined_without_a_restart(tmp_path: Path) -> None:
    port = free_port()
    with running_exporter(tmp_path, None, *exporter_args(port)) as exporter:
        # No router yet: the exporter serves, and counts its attempts to reach one.
        wait_for(
            lambda: metric(
                exporter, "overseer_source_errors_total", transport="zenoh", reason="router_unreachable"
            ),
            30,
            message="unreachable router counted",
        )
        assert exporter.get_json("/api/v1/robots")["robots"] == []
        router = start_router(tmp_path, port)
        try:
            with running_simulator(tmp_path, 0, *simulator_args(port, "--robots=1", "--components=5")):
                wait_until_heard(exporter, "robot1", 10, timeout=45)
            assert exporter.process.poll() is None
        finally:
            router.stop()


def test_a_killed_robot_is_down_at_once_through_liveliness_and_up_when_it_returns(tmp_path: Path) -> None:
    victim_args = simulator_args(port := free_port(), "--robots=1", "--namespace-prefix=victim")
    with (
        running_router(tmp_path, port),
        # The robots start first: their tokens reach the exporter as liveliness history.
        running_simulator(tmp_path, 0, *simulator_args(port, "--robots=1", "--namespace-prefix=keeper")),
        running_simulator(tmp_path, 0, *victim_args) as victim,
    ):
        time.sleep(1)
        with running_exporter(tmp_path, None, *exporter_args(port, "--fleet.robot-timeout=60s")) as exporter:
            wait_until_heard(exporter, "victim1", 15)
            wait_until_heard(exporter, "keeper1", 15)
            # The event history checks robots once a second: let it see victim1 up before it goes.
            wait_for(lambda: robot_events(exporter, "victim1", "robot_up"), 10, message="victim1 up event")
            victim.process.send_signal(signal.SIGKILL)
            killed_at = time.monotonic()
            wait_for(lambda: robot_up(exporter, "victim1") == 0.0, 10, interval=0.1, message="victim1 down")
            down_after = time.monotonic() - killed_at
            assert down_after < 5, f"down after {down_after:.1f}s; the robot timeout is 60s"
            document = exporter.robot("victim1")
            assert document is not None and document["up"] is False and document["level"] == LEVELS["STALE"]
            assert document["publisher_alive"] is False
            assert robot_up(exporter, "keeper1") == 1.0
            check = run_check("--url", exporter.url, "-r", "victim1")
            assert check.output.startswith("UNKNOWN - victim1 is down: its diagnostics publisher left"), check
            down = wait_for(lambda: robot_events(exporter, "victim1", "robot_down"), 10, message="down event")
            assert down[0]["message"] == "its diagnostics publisher left"
            assert down[0]["time"] <= time.time()  # when it left, not last message + robot timeout
            with running_simulator(tmp_path, 0, *victim_args):
                wait_for(lambda: robot_up(exporter, "victim1") == 1.0, 15, interval=0.1, message="victim1 up")
                assert exporter.robot("victim1")["level"] == LEVELS["ERROR"]  # type: ignore[index]


def test_a_robot_with_another_type_hash_is_heard_and_the_mismatch_counted(tmp_path: Path) -> None:
    other_hash = "RIHS01_" + "ab" * 32
    with (
        running_router(tmp_path) as port,
        running_exporter(tmp_path, None, *exporter_args(port)) as exporter,
        running_simulator(
            tmp_path, 0, *simulator_args(port, "--robots=1", f"--zenoh.type-hash={other_hash}")
        ),
    ):
        wait_until_heard(exporter, "robot1", 15)
        mismatches = metric(
            exporter, "overseer_source_errors_total", transport="zenoh", reason="type_hash_mismatch"
        )
        assert mismatches is not None and mismatches >= 1


def test_hostile_keys_and_payloads_are_counted_and_the_exporter_keeps_serving(tmp_path: Path) -> None:
    good = encode_diagnostic_array(DiagnosticArray(0, 0, "", (DiagnosticStatus(1, "/a", "warm", "", ()),)))
    hostile = {
        f"0/robot9/diagnostics_agg/std_msgs::msg::dds_::String_/{DIAGNOSTIC_ARRAY_HASH}": good,  # wrong type
        data_key(0, "garbage", "diagnostics_agg"): b"\x00\x01\x00\x00" + bytes(range(256)) * 4,
        data_key(0, "short", "diagnostics_agg"): b"\x00",
        data_key(0, "huge", "diagnostics_agg"): b"\x00\x01\x00\x00" + b"\xff" * (4 << 20),
        data_key(0, "wei rd☃/ns", "diagnostics_agg"): good,  # not a ROS namespace
        "caf\u00e9-robot/diagnostics_agg": good,  # bridge key with a namespace no ROS robot can have
        f"0/{DIAGNOSTIC_ARRAY_TYPE}/diagnostics_agg": good,  # the type where a namespace goes
    }
    with (
        running_router(tmp_path) as port,
        # One worker: hand-made keys have no publisher token, which workers follow robots by.
        running_exporter(tmp_path, None, *exporter_args(port, "--ingest.workers=1")) as exporter,
        client_session(port) as session,
    ):
        wait_for(lambda: session.info.routers_zid(), 10, message="test session connected")

        def publish_and_count() -> bool:
            for key, payload in hostile.items():
                session.put(key, payload)
            session.put(data_key(0, "fine", "diagnostics_agg"), good)
            token = f"@ros2_lv/0/zz/0/1/MP/%/%/n/%{'x' * 300}%diagnostics_agg/{DIAGNOSTIC_ARRAY_TYPE}/h/q"
            session.liveliness().declare_token(token).undeclare()  # type: ignore[no-untyped-call]
            errors = {
                reason: metric(exporter, "overseer_source_errors_total", transport="zenoh", reason=reason)
                for reason in ("unexpected_type", "invalid_namespace")
            }
            decode_errors = metric(
                exporter, "overseer_messages_total", transport="zenoh", result="decode_error"
            )
            return all(errors.values()) and (decode_errors or 0) >= 3 and exporter.robot("fine") is not None

        wait_for(publish_and_count, 30, interval=0.5, message="every hostile input counted")
        assert exporter.robot("fine")["level"] == LEVELS["WARN"]  # type: ignore[index]
        names = {r["robot"] for r in exporter.get_json("/api/v1/robots")["robots"]}
        assert not names & {"robot9", "wei rd☃/ns", "caf\u00e9-robot", "0", "domain0"}
        assert exporter.get("/-/healthy") and exporter.process.poll() is None


@pytest.mark.parametrize("workers", [1, 2])
def test_samples_a_publisher_numbered_and_the_exporter_never_heard_are_counted_lost(
    tmp_path: Path, workers: int
) -> None:
    payload = encode_diagnostic_array(DiagnosticArray(0, 0, "", (DiagnosticStatus(0, "/a", "ok", "", ()),)))

    def counted(result: str) -> float:
        return metric(exporter, "overseer_messages_total", transport="zenoh", result=result) or 0

    with (
        running_router(tmp_path) as port,
        running_exporter(tmp_path, None, *exporter_args(port, f"--ingest.workers={workers}")) as exporter,
        client_session(port) as session,
    ):
        wait_for(lambda: session.info.routers_zid(), 10, message="test session connected")
        token = publisher_token(
            0, str(session.zid()), 10, "lossy", "aggregator", "diagnostics_agg", DIAGNOSTIC_ARRAY_HASH
        )
        # Kept for the test: a token undeclared (collected) at once may never reach a worker, which would
        # then never follow the robot's topic.
        declared = session.liveliness().declare_token(token)
        gid, key, numbers = publisher_gid(token), data_key(0, "lossy", "diagnostics_agg"), [0]

        def put(number: int) -> None:
            numbers[0] = number
            session.put(key, payload, attachment=attachment(number, time.time_ns(), gid))

        def settled() -> float | None:
            before = counted("received")
            time.sleep(0.5)
            return before if counted("received") == before else None

        def put_next_until_heard() -> bool:
            put(numbers[0] + 1)
            return counted("received") > 0  # the robot is known from its token alone: wait for a sample

        # Numbered one by one, as rmw_zenoh does, until a worker follows the robot: what it did not hear
        # before then is not a gap (nothing was heard to measure from).
        wait_for(put_next_until_heard, 30, interval=0.1, message="the numbered publisher heard")
        received = wait_for(settled, 10, message="the samples put meanwhile all heard")
        assert counted("lost") == 0
        put(numbers[0] + 6)  # five never sent on: lost on the way
        put(numbers[0] + 1)
        wait_for(lambda: counted("received") == received + 2, 10, message="the two samples after the gap")
        assert counted("lost") == 5
        highest = numbers[0]
        put(1)  # stray numbers, lower than the highest heard: neither a loss nor where counting goes on from
        put(2)
        put(highest + 1)
        wait_for(lambda: counted("received") == received + 5, 10, message="the stray samples")
        assert counted("lost") == 5
        put(highest + 3)  # counted from the highest heard, not from the stray 2
        wait_for(lambda: counted("received") == received + 6, 10, message="the sample after one more gap")
        assert counted("lost") == 6
        assert "6 samples of lossy's lossy/diagnostics_agg" not in exporter.log()  # 6 is no power of ten
        assert "5 samples of lossy's lossy/diagnostics_agg" in exporter.log()  # the first loss, named
        declared.undeclare()  # type: ignore[no-untyped-call]


def test_the_simulator_sends_rmw_zenoh_attachment_and_liveliness_tokens(tmp_path: Path) -> None:
    samples: list[zenoh.Sample] = []
    tokens: list[str] = []
    with running_router(tmp_path) as port, client_session(port) as session:
        session.declare_subscriber("0/**", samples.append)
        session.liveliness().declare_subscriber("@ros2_lv/0/**", lambda s: tokens.append(str(s.key_expr)))
        with running_simulator(tmp_path, 0, *simulator_args(port, "--robots=1", "--namespace-prefix=a/b")):
            wait_for(lambda: len(samples) >= 2 and len(tokens) >= 2, 20, message="two samples and the tokens")
    first, second = samples[0], samples[1]
    assert str(first.key_expr) == f"0/a/b1/diagnostics_agg/{DIAGNOSTIC_ARRAY_TYPE}/{DIAGNOSTIC_ARRAY_HASH}"
    assert first.payload.to_bytes()[:4] == b"\x00\x01\x00\x00"
    assert first.attachment is not None and second.attachment is not None
    # Read back with Zenoh's own deserializer, as rmw_zenoh does: 33 bytes, the GID the token's hash.
    layout: Any = tuple[Int64, Int64, list[UInt8]]
    fields: tuple[Any, ...] = z_deserialize(layout, first.attachment)
    sequence1, stamp, gid = fields
    assert len(first.attachment.to_bytes()) == 33
    assert len(gid) == 16 and abs(stamp / 1e9 - time.time()) < 60
    assert z_deserialize(layout, second.attachment)[0] == sequence1 + 1
    publisher = next(t for t in tokens if "/MP/" in t)
    chunks = publisher.split("/")
    assert chunks[5:] == [
        "MP",
        "%",
        "%a%b1",
        "diagnostic_aggregator",
        "%a%b1%diagnostics_agg",
        DIAGNOSTIC_ARRAY_TYPE,
        DIAGNOSTIC_ARRAY_HASH,
        "::,:,:,:,,",
    ]
    assert any(t.endswith("/NN/%/%a%b1/diagnostic_aggregator") for t in tokens)
    # rmw_zenoh's GID of an entity: XXH3-128 of its liveliness token, low half first (little-endian)
    assert bytes(gid) == xxhash.xxh3_128(publisher.encode()).intdigest().to_bytes(16, "little")


def test_the_shard_and_the_robot_cap_hold_over_zenoh(tmp_path: Path) -> None:
    # Of robot1…robot8, shard 0/2 owns robot1, robot2, robot3 and robot8; the cap keeps two of them.
    config = tmp_path / "overseer.yml"
    config.write_text("fleet:\n  max_robots: 2\n")
    with (
        running_router(tmp_path) as port,
        running_exporter(
            tmp_path, None, *exporter_args(port, f"--config.file={config}", "--shard=0/2")
        ) as exporter,
        running_simulator(tmp_path, 0, *simulator_args(port, "--robots=8", "--components=5")),
    ):
        wait_for(
            lambda: metric(exporter, "overseer_statuses_dropped_total", reason="robot_limit"),
            30,
            message="robots beyond the cap counted",
        )
        robots = {r["robot"] for r in exporter.get_json("/api/v1/robots")["robots"]}
        assert len(robots) == 2 and robots <= {"robot1", "robot2", "robot3", "robot8"}
        wait_for(
            lambda: metric(exporter, "overseer_messages_total", transport="zenoh", result="dropped"),
            10,
            message="messages of refused robots counted",
        )


def test_a_restarted_router_is_joined_again_and_its_robots_with_it(tmp_path: Path) -> None:
    port = free_port()
    router = start_router(tmp_path, port)
    try:
        with (
            running_exporter(tmp_path, None, *exporter_args(port, "--fleet.robot-timeout=60s")) as exporter,
            running_simulator(tmp_path, 0, *simulator_args(port, "--robots=1", "--components=5")),
        ):
            wait_until_heard(exporter, "robot1", 10)
            router.stop()
            # The exporter cannot hear the robot any more: its token is gone with the link.
            wait_for(lambda: robot_up(exporter, "robot1") == 0.0, 10, interval=0.1, message="robot1 down")
            router = start_router(tmp_path, port)
            wait_for(lambda: robot_up(exporter, "robot1") == 1.0, 30, interval=0.2, message="robot1 up again")
            received = metric(exporter, "overseer_messages_total", transport="zenoh", result="received") or 0
            wait_for(
                lambda: (
                    (metric(exporter, "overseer_messages_total", transport="zenoh", result="received") or 0)
                    > received + 1
                ),
                10,
                message="messages flowing again",
            )
    finally:
        router.stop()


def test_two_sites_routers_that_come_up_later_are_both_followed(tmp_path: Path) -> None:
    """Two routers that know nothing of each other (two sites): the exporter hears the robots of both.

    A client session keeps a link to one router only, so with several endpoints the exporter is a peer.
    """
    first, second = free_port(), free_port()
    args = ("--dds.disabled", f"--zenoh.connect={endpoint(first)}", f"--zenoh.connect={endpoint(second)}")
    with running_exporter(tmp_path, None, *args) as exporter:
        routers = [start_router(tmp_path, first), start_router(tmp_path, second)]
        try:
            with (
                running_simulator(
                    tmp_path,
                    0,
                    *simulator_args(first, "--robots=1", "--components=5", "--namespace-prefix=a"),
                ),
                running_simulator(
                    tmp_path,
                    0,
                    *simulator_args(second, "--robots=1", "--components=5", "--namespace-prefix=b"),
                ),
            ):
                wait_until_heard(exporter, "a1", 10, timeout=45)
                wait_until_heard(exporter, "b1", 10, timeout=45)
        finally:
            for router in routers:
                router.stop()
