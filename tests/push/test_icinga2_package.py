"""A fleet first heard is registered in a real Icinga 2 in one stage of the exporter's config package.

Its results then repeat spread over the interval, not all at once as they were first sent.

Its own Icinga 2 daemon (a stage reloads it, which the other push tests' daemon should not see), with
two users: the shipped push ApiUser example as it is, and the same with its optional config package
permissions switched on. Each test runs exporters in the test process, their models filled before the
push first looks, with robots of their own.
"""

from __future__ import annotations

import json
import logging
import threading
import time
from collections import Counter
from collections.abc import Callable, Collection, Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest

from overseer.app import Exporter
from overseer.fleet.local import LocalFleet
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import FleetSnapshot
from overseer.push import icinga2_push
from overseer.push.icinga2_names import host_name
from overseer.push.icinga2_objects import BULK_OBJECTS
from overseer.push.icinga2_package import dsl_string, object_text, package_name
from overseer.push.icinga2_push import Icinga2Push
from testbed.icinga2 import (
    PUSH_BULK_USER,
    PUSH_USER,
    Icinga2,
    push_api_user,
    push_bulk_api_user,
    push_config,
    running_icinga2,
)
from testbed.in_process import call, in_process_exporter
from testbed.processes import wait_for

pytestmark = pytest.mark.servers

ROBOTS = 30  # a host, its robot service and two group services each: 120 objects at once
HANDMADE = """object Host "clash.robot3" {
	check_command = "dummy"
	vars.owner = "operator"
}
"""
HOSTILE = 'robot "7" \\ é\tbad'  # quotes, a backslash, UTF-8 and a control character in vars.ros_robot


@pytest.fixture(scope="module")
def icinga(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Icinga2]:
    """The push ApiUser example, as it is and with config packages allowed, and an operator's host."""
    users = push_api_user() + push_bulk_api_user()
    with running_icinga2(tmp_path_factory.mktemp("icinga2"), users + HANDMADE) as daemon:
        yield daemon


def robot_array(level: int, groups: tuple[str, ...] = ("Power", "Motor")) -> DiagnosticArray:
    """An aggregator's array with one component in each of `groups`, the first at `level`."""
    return DiagnosticArray(
        0,
        0,
        "",
        tuple(
            DiagnosticStatus(level if index == 0 else 0, f"/{group}/Part", "state", "hw", (("k", "v"),))
            for index, group in enumerate(groups)
        ),
    )


@contextmanager
def exporter(
    tmp_path: Path,
    daemon: Icinga2,
    exporter_id: str,
    user: str,
    robots: list[str],
    robot_timeout: str = "1h",
    groups: tuple[str, ...] = ("Power", "Motor"),
    interval: str = "1h",
) -> Iterator[Exporter]:
    """An in-process exporter pushing `robots` (in its model before the push starts) to `daemon` as `user`.

    Each robot's first array has a component in each of `groups`.
    """
    config = push_config(tmp_path, daemon, exporter_id, interval, timeout="5s", username=user)
    section = json.loads(config.read_text())["icinga2"]

    def fill(running: Exporter) -> None:
        assert running.model is not None
        for index, robot in enumerate(robots):
            running.model.apply(robot, robot_array(2 if index % 3 == 0 else 0, groups), "dds")

    with in_process_exporter(
        tmp_path,
        before_start=fill,
        icinga2=section,
        fleet={"stale_after": "1s", "robot_timeout": robot_timeout},
    ) as running:
        yield running


def hosts(daemon: Icinga2, prefix: str) -> dict[str, dict[str, Any]]:
    """The hosts whose names start with `prefix`: their package, vars and last result."""
    answer = daemon.api(
        "GET", "/v1/objects/hosts", {"attrs": ["name", "package", "vars", "last_check_result"]}
    )
    return {item["name"]: item["attrs"] for item in answer["results"] if item["name"].startswith(prefix)}


def services(daemon: Icinga2, host: str) -> dict[str, dict[str, Any]]:
    """The services of `host` by short name: their package and last result."""
    answer = daemon.api(
        "GET", "/v1/objects/services", {"attrs": ["name", "host_name", "package", "last_check_result"]}
    )
    return {
        item["attrs"]["name"]: item["attrs"]
        for item in answer["results"]
        if item["attrs"]["host_name"] == host
    }


def all_pushed(daemon: Icinga2, prefix: str, count: int, per_host: int) -> bool:
    """Whether `count` hosts of `prefix` and `per_host` services each exist, every one with a result."""
    found = hosts(daemon, prefix)
    if len(found) != count or any(host["last_check_result"] is None for host in found.values()):
        return False
    for host in found:
        made = services(daemon, host)
        if len(made) != per_host or any(service["last_check_result"] is None for service in made.values()):
            return False
    return True


def stages_counted(running: Exporter, result: str) -> float:
    """overseer_icinga2_package_stages_total of one result on the exporter's /metrics (0 when absent)."""
    _, body = call(running, "/metrics")
    prefix = f'overseer_icinga2_package_stages_total{{result="{result}"}} '
    lines = [line for line in body.decode().splitlines() if line.startswith(prefix)]
    return float(lines[0].removeprefix(prefix)) if lines else 0.0


def distinct_sets(running: Exporter) -> tuple[int, int]:
    """How many distinct objects hold the push's services made, and packaged, for its hosts."""
    assert running.icinga2_push is not None
    objects = running.icinga2_push._objects
    if not objects.found:  # not yet looked for in Icinga
        return -1, -1
    made, packaged = list(objects.created.values()), list(objects._packaged.values())  # the push goes on
    return len({id(services) for services in made}), len({id(services) for services in packaged})


def stages(daemon: Icinga2, exporter_id: str) -> list[str]:
    """The stages Icinga keeps of the exporter's package."""
    for package in daemon.api("GET", "/v1/config/packages", {})["results"]:
        if package["name"] == package_name(exporter_id):
            return list(package["stages"])
    return []


def test_dsl_strings_escape_what_icinga_reads_specially() -> None:
    assert dsl_string('a"b\\c\nd\te$f\x01') == '"a\\"b\\\\c\\nd\\te$$f\\001"'
    text = object_text("Service", "svc", {"check_command": "dummy", "vars.x": [1, True, None]}, "tmpl", "h")
    assert text == (
        'object Service "svc" {\n  import "tmpl"\n  host_name = "h"\n  check_command = "dummy"\n'
        '  vars["x"] = [1, true, null]\n}\n'
    )


def test_a_fleet_first_heard_is_registered_in_one_stage(
    icinga: Icinga2, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, logger="overseer.push")
    robots = [f"pkg/robot{index}" for index in range(ROBOTS - 1)] + [f"pkg/{HOSTILE}"]
    assert ROBOTS * 4 >= BULK_OBJECTS
    with exporter(tmp_path, icinga, "bulk", PUSH_BULK_USER, robots) as running:
        wait_for(lambda: all_pushed(icinga, "pkg.", ROBOTS, 3), timeout=90, message="every robot pushed")
        assert "registered in one stage of package overseer-bulk" in caplog.text
        assert (stages_counted(running, "ok"), stages_counted(running, "refused")) == (1, 0)
    found = hosts(icinga, "pkg.")
    assert {host["package"] for host in found.values()} == {"overseer-bulk"}
    assert found[host_name(f"pkg/{HOSTILE}")]["vars"]["ros_robot"] == f"pkg/{HOSTILE}"
    assert {service["package"] for service in services(icinga, "pkg.robot0").values()} == {"overseer-bulk"}
    assert found["pkg.robot0"]["last_check_result"]["output"].startswith("UP - pkg/robot0")
    assert len(stages(icinga, "bulk")) == 1


def test_a_fleet_beyond_the_queue_is_registered_in_one_stage_its_results_built_a_few_robots_at_a_time(
    icinga: Icinga2, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    held: list[int] = []  # the results queued after each look
    look = Icinga2Push._queue

    def watched(push: Icinga2Push, now: float) -> None:
        look(push, now)
        held.append(len(push._urgent) + len(push._pending))

    # Two robots' results (a host, robot and two group services each): the other 28 are owed theirs.
    monkeypatch.setattr(icinga2_push, "QUEUED_RESULTS", 8)
    monkeypatch.setattr(Icinga2Push, "_queue", watched)
    robots = [f"owed/robot{index}" for index in range(ROBOTS)]
    with exporter(tmp_path, icinga, "owed", PUSH_BULK_USER, robots) as running:
        wait_for(lambda: all_pushed(icinga, "owed.", ROBOTS, 3), timeout=90, message="every robot pushed")
        assert (stages_counted(running, "ok"), stages_counted(running, "rejected")) == (1, 0)
        assert distinct_sets(running) == (1, 1)  # the same services for every robot: one set, not 30
    assert {host["package"] for host in hosts(icinga, "owed.").values()} == {"overseer-owed"}
    # At most one robot's results beyond the cap, where the whole fleet's 120 were held at once.
    assert held and max(held) <= 8 + 3, held


def test_a_fleet_first_sent_at_once_repeats_spread_over_the_interval(
    icinga: Icinga2, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    interval = 4.0
    robots = [f"spread/robot{index}" for index in range(ROBOTS)]
    asked: list[int] = []  # how many robots each snapshot the push asked for held
    snapshot_of = LocalFleet.robots_snapshot

    def counted(fleet: LocalFleet, names: Collection[str]) -> FleetSnapshot:
        asked.append(len(names))
        return snapshot_of(fleet, names)

    monkeypatch.setattr(LocalFleet, "robots_snapshot", counted)
    monkeypatch.setattr(icinga2_push, "SNAPSHOT_ROBOTS", 7)  # the fleet first heard is asked 7 at a time
    with exporter(tmp_path, icinga, "spread", PUSH_BULK_USER, robots, interval=f"{interval:g}s"):
        wait_for(lambda: all_pushed(icinga, "spread.", ROBOTS, 3), timeout=90, message="every robot pushed")
        time.sleep(2)  # the components go STALE after 1 s: that change goes to every robot at once too
        sent: dict[str, set[float]] = {}  # host → when Icinga received each of its results
        watched_until = time.monotonic() + 2 * interval
        while time.monotonic() < watched_until:
            for host, attrs in hosts(icinga, "spread.").items():
                sent.setdefault(host, set()).add(attrs["last_check_result"]["execution_end"])
            time.sleep(0.2)
    first = min(min(times) for times in sent.values())
    repeats = sorted(when for times in sent.values() for when in times if when > first + interval / 4)
    assert len(sent) == ROBOTS and all(len(times) >= 2 for times in sent.values())  # every robot repeated
    assert asked and max(asked) == 7
    quarters = Counter(int((when - first) / (interval / 4)) % 4 for when in repeats)
    # Sent together, every repeat falls in one quarter of the interval; spread, none holds most of them.
    assert max(quarters.values()) <= 0.6 * len(repeats), (quarters, repeats)


def test_robots_heard_before_their_groups_have_the_group_services_registered_in_one_stage(
    icinga: Icinga2, tmp_path: Path, caplog: pytest.LogCaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    # As a fleet declared before it publishes (an inventory, tokens heard first): at 10,000 robots the
    # group services made one a call took Icinga hours, where one stage takes a minute.
    caplog.set_level(logging.INFO, logger="overseer.push")
    robots = [f"early/robot{index}" for index in range(BULK_OBJECTS // 2)]  # a host and a robot service each
    with exporter(tmp_path, icinga, "early", PUSH_BULK_USER, robots, groups=()) as running:
        assert running.model is not None
        wait_for(lambda: all_pushed(icinga, "early.", len(robots), 1), timeout=90, message="the hosts pushed")
        assert stages_counted(running, "ok") == 1
        # Every robot's groups at once, as the push looks (its digests, then its robots): no look between
        # two robots' arrays.
        gate = threading.RLock()
        snapshot, robots_snapshot = running.model.snapshot, running.model.robots_snapshot

        def gated() -> FleetSnapshot:
            with gate:
                return snapshot()

        def gated_robots(names: Iterable[str]) -> FleetSnapshot:
            with gate:
                return robots_snapshot(names)

        monkeypatch.setattr(running.model, "snapshot", gated)
        monkeypatch.setattr(running.model, "robots_snapshot", gated_robots)
        with gate:
            for robot in robots:
                running.model.apply(robot, robot_array(0), "dds")
        wait_for(lambda: all_pushed(icinga, "early.", len(robots), 3), timeout=90, message="every group")
        assert (stages_counted(running, "ok"), stages_counted(running, "rejected")) == (2, 0)
        assert f"0 hosts and {2 * len(robots)} services registered in one stage" in caplog.text
    for host in hosts(icinga, "early."):
        assert {service["package"] for service in services(icinga, host).values()} == {"overseer-early"}
    assert len(stages(icinga, "early")) == 1  # the first stage removed once the second ran


def test_a_restarted_exporter_keeps_its_stage_and_deletes_a_forgotten_robot_with_the_next(
    icinga: Icinga2, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, logger="overseer.push")
    robots = [f"again/robot{index}" for index in range(ROBOTS)]
    with exporter(tmp_path, icinga, "again", PUSH_BULK_USER, robots):
        wait_for(lambda: all_pushed(icinga, "again.", ROBOTS, 3), timeout=90, message="every robot pushed")
    first = stages(icinga, "again")
    with exporter(tmp_path, icinga, "again", PUSH_BULK_USER, robots, robot_timeout="2s") as running:
        assert running.model is not None
        wait_for(lambda: "found 30 hosts of this exporter (again)" in caplog.text, timeout=30)
        # As Icinga's answer listed them, a set each: shared once found.
        wait_for(lambda: distinct_sets(running) == (1, 1), timeout=10, message="one set of services")
        # A group robot1 did not have: its service is made by a call of its own, outside the package.
        running.model.apply("again/robot1", robot_array(0, ("Power", "Motor", "Camera")), "dds")
        wait_for(
            lambda: (
                services(icinga, "again.robot1").get("ros-diagnostics-Camera", {}).get("package") == "_api"
            ),
            timeout=30,
            message="the new group's service",
        )
        wait_for(lambda: running.model.retire("again/robot1") == "retired", timeout=30, message="robot1 down")
        wait_for(lambda: "again.robot1" not in hosts(icinga, "again."), timeout=90, message="robot1 deleted")
        assert len(hosts(icinga, "again.")) == ROBOTS - 1
        assert not services(icinga, "again.robot1")
        # The deletion's stage, counted once Icinga runs it; the restart deployed nothing.
        wait_for(lambda: stages_counted(running, "ok") == 1, timeout=10, message="the stage counted")
    assert stages(icinga, "again") != first and len(stages(icinga, "again")) == 1  # the old one removed
    assert "refused a stage" not in caplog.text and "rejected a stage" not in caplog.text


def test_without_the_package_permissions_robots_are_registered_one_object_a_call(
    icinga: Icinga2, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, logger="overseer.push")
    robots = [f"narrow/robot{index}" for index in range(ROBOTS)]
    with exporter(tmp_path, icinga, "narrow", PUSH_USER, robots) as running:
        wait_for(lambda: all_pushed(icinga, "narrow.", ROBOTS, 3), timeout=120, message="every robot pushed")
        assert "the ApiUser may not deploy config packages" in caplog.text
        assert (stages_counted(running, "ok"), stages_counted(running, "refused")) == (0, 1)
        assert distinct_sets(running) == (1, 0)  # made one object a call, a set each time: still one
    assert {host["package"] for host in hosts(icinga, "narrow.").values()} == {"_api"}
    assert not stages(icinga, "narrow")


def test_a_stage_icinga_rejects_changes_nothing_and_robots_are_registered_one_a_call(
    icinga: Icinga2, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, logger="overseer.push")
    robots = [f"clash/robot{index}" for index in range(ROBOTS)]  # clash.robot3 is an operator's host
    with exporter(tmp_path, icinga, "clash", PUSH_BULK_USER, robots) as running:
        wait_for(lambda: len(hosts(icinga, "clash.")) == ROBOTS, timeout=120, message="every host")
        wait_for(lambda: all_pushed(icinga, "clash.robot0", 1, 3), timeout=60, message="robot0 pushed")
        assert "Icinga 2 rejected a stage of package overseer-clash registering 30 robots" in caplog.text
        assert "re-defined" in caplog.text  # Icinga's own reason, from the stage's startup log
        assert "host clash.robot3 exists and was not made by this exporter" in caplog.text
        assert (stages_counted(running, "rejected"), stages_counted(running, "ok")) == (1, 0)
    made = hosts(icinga, "clash.")
    assert made["clash.robot3"]["vars"] == {"owner": "operator"}  # left alone
    assert {host["package"] for name, host in made.items() if name != "clash.robot3"} == {"_api"}
    assert not stages(icinga, "clash")  # the rejected stage is not kept


def test_registered_robots_results_go_on_while_a_stage_for_new_robots_is_deployed(
    icinga: Icinga2, tmp_path: Path
) -> None:
    # At 10,000 robots Icinga validates and loads a stage for a minute or more: deployed by the push's own
    # thread, it held back every registered robot's results that long, past their TTL.
    robots = [f"beside/robot{index}" for index in range(ROBOTS)]
    with exporter(tmp_path, icinga, "beside", PUSH_BULK_USER, robots) as running:
        assert running.model is not None and running.icinga2_push is not None
        wait_for(lambda: all_pushed(icinga, "beside.robot", ROBOTS, 3), timeout=90, message="robots pushed")
        package = running.icinga2_push._objects._package
        assert package is not None
        deploy, started, release = package.deploy, threading.Event(), threading.Event()

        def held_back(text: str, loaded: Callable[[], bool]) -> None:
            """The real deploy, once the test lets it go: a stage Icinga takes long to validate."""
            started.set()
            assert release.wait(60), "the test never let the stage go"
            deploy(text, loaded)

        package.deploy = held_back  # type: ignore[method-assign]
        newcomers = [f"beside/new{index}" for index in range(ROBOTS)]
        for robot in newcomers:
            running.model.apply(robot, robot_array(0), "dds")
        assert started.wait(30), "no stage for the newcomers"
        changed_at = time.time()
        running.model.apply("beside/robot1", robot_array(2), "dds")  # a change while the stage waits

        def delivered() -> bool:
            result = services(icinga, "beside.robot1")["ros-diagnostics-Power"]["last_check_result"]
            return bool(result["execution_end"] >= changed_at)  # its only results since: of the change

        try:
            wait_for(delivered, timeout=30, message="robot1's change delivered while the stage is deployed")
            assert hosts(icinga, "beside.new") == {}  # none made one a call beside the stage
        finally:
            release.set()
        wait_for(lambda: all_pushed(icinga, "beside.new", ROBOTS, 3), timeout=90, message="newcomers pushed")
        assert (stages_counted(running, "ok"), stages_counted(running, "rejected")) == (2, 0)
        counts = running.icinga2_push.stats.read()[0]
        assert [reason for reason, count in counts.items() if count and reason != "ok"] == []  # the reload
    assert {host["package"] for host in hosts(icinga, "beside.").values()} == {"overseer-beside"}
