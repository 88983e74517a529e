"""Faults survived with nothing lost: killed publishers, a restarted exporter, a cut link, a dead Prometheus.

Each test breaks one thing for real (SIGKILL, SIGSTOP, a veth link taken down), watches the exporter tell
the truth while it is broken (robot down, components STALE), and ends by checking the whole fleet is back
with every component at its exact level and no message counted as lost. Recovery times are printed.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest

from overseer.levels import Level
from overseer.simulator.design import aggregated_statuses, initial_levels, leaf_components
from testbed.alertmanager import running_alertmanager
from testbed.netns import VethNamespace, veth_namespace
from testbed.ports import free_port
from testbed.processes import (
    Exporter,
    RunningProcess,
    overseer_command,
    running_exporter,
    running_simulator,
    spawn,
    wait_for,
    wait_until_healthy,
)
from testbed.prometheus import running_prometheus, shipped_config

pytestmark = pytest.mark.servers  # every test here starts real servers or middleware

STALE_AFTER, ROBOT_TIMEOUT = 1.0, 2.0
FAST = (f"--fleet.stale-after={STALE_AFTER:g}s", f"--fleet.robot-timeout={ROBOT_TIMEOUT:g}s")


def expected_levels(components: int) -> dict[str, str]:
    """Each component's state as the simulator publishes it (one WARN and one ERROR leaf)."""
    leaves = leaf_components(components)
    return {
        s.name: Level(s.level).name for s in aggregated_statuses(leaves, initial_levels(leaves, 1, 1), set())
    }


def states(robot: dict[str, Any]) -> dict[str, str]:
    """Component name → state in an API robot document."""
    return {component["name"]: component["state"] for component in robot["components"]}


def whole(exporter: Exporter, robots: list[str], components: int) -> bool:
    """Every robot up with exactly the simulator's components at their exact levels."""
    expected = expected_levels(components)
    for name in robots:
        robot = exporter.robot(name)
        if robot is None or not robot["up"] or states(robot) != expected:
            return False
    return True


def down_and_stale(exporter: Exporter, name: str) -> bool:
    """The robot is known, down, and every component of it STALE."""
    robot = exporter.robot(name)
    return robot is not None and not robot["up"] and set(states(robot).values()) == {"STALE"}


def lost(exporter: Exporter) -> float:
    """Messages the exporter could not use: decode errors and drops."""
    total = 0.0
    for line in exporter.get("/metrics").decode().splitlines():
        if line.startswith("overseer_messages_total{") and 'result="received"' not in line:
            total += float(line.rsplit(" ", 1)[1])
    return total


def timed(predicate: Any, timeout: float, message: str) -> float:
    """Seconds until `predicate` holds (polled every 50 ms)."""
    started = time.monotonic()
    wait_for(predicate, timeout, interval=0.05, message=message)
    return time.monotonic() - started


def test_publisher_killed_with_sigkill_goes_down_and_comes_back_whole(
    tmp_path: Path, dds_domain: int
) -> None:
    robots, args = ["robot1", "robot2"], ("--robots=2", "--components=10", "--rate=4")
    with running_exporter(tmp_path, dds_domain, *FAST) as exporter:
        pid = exporter.process.pid
        with running_simulator(tmp_path, dds_domain, *args) as simulator:
            wait_for(lambda: whole(exporter, robots, 10), 30, message="the fleet")
            simulator.process.kill()
            killed = time.monotonic()
            simulator.process.wait()
            wait_for(
                lambda: all(down_and_stale(exporter, r) for r in robots), 10, interval=0.05, message="down"
            )
            down = time.monotonic() - killed
        with running_simulator(tmp_path, dds_domain, *args):
            back = timed(lambda: whole(exporter, robots, 10), 30, "the fleet back")
        assert exporter.process.pid == pid and exporter.process.poll() is None
        assert lost(exporter) == 0
    print(
        f"\nSIGKILLed publisher: robots down and STALE {down:.1f}s after the kill, "
        f"whole {back:.1f}s after its restart"
    )
    assert down <= ROBOT_TIMEOUT + 1.5


def test_robot_back_with_other_components_keeps_the_vanished_ones_stale_then_forgets_them(
    tmp_path: Path, dds_domain: int
) -> None:
    expire_after = 8.0
    with running_exporter(tmp_path, dds_domain, *FAST, f"--fleet.expire-after={expire_after:g}s") as exporter:
        with running_simulator(
            tmp_path, dds_domain, "--robots=1", "--components=10", "--rate=4"
        ) as simulator:
            wait_for(lambda: whole(exporter, ["robot1"], 10), 30, message="robot1 with 15 components")
            simulator.process.kill()
            simulator.process.wait()
        with running_simulator(tmp_path, dds_domain, "--robots=1", "--components=3", "--rate=4"):
            now, before = expected_levels(3), expected_levels(10)
            vanished = set(before) - set(now)
            assert vanished and set(now) <= set(before)

            def new_set_current_old_set_stale() -> bool:
                robot = exporter.robot("robot1")
                assert robot is not None
                found = states(robot)
                current = robot["up"] and all(found[name] == state for name, state in now.items())
                return current and all(found.get(name) == "STALE" for name in vanished)

            wait_for(new_set_current_old_set_stale, 30, interval=0.2, message="new components, old STALE")
            forgotten = timed(
                lambda: whole(exporter, ["robot1"], 3), expire_after + 10, "the vanished expired"
            )
        metrics = exporter.get("/metrics").decode()
        assert all(f'component="{name}"' not in metrics for name in vanished)
        assert lost(exporter) == 0
    print(
        f"\nrobot back with {len(now)} of {len(before)} components: the other {len(vanished)} STALE, "
        f"then forgotten {forgotten:.1f}s later"
    )
    assert forgotten <= expire_after + 2


def test_restarted_exporter_has_the_whole_fleet_within_one_period_after_discovery(
    tmp_path: Path, dds_domain: int
) -> None:
    robots, period = [f"robot{i}" for i in range(1, 6)], 1.0
    port = free_port()
    with running_simulator(tmp_path, dds_domain, "--robots=5", "--components=10", f"--rate={1 / period:g}"):
        with running_exporter(tmp_path, dds_domain, *FAST, port=port) as first:
            wait_for(lambda: whole(first, robots, 10), 30, message="the fleet")
            first.process.kill()
            first.process.wait()
        with running_exporter(tmp_path, dds_domain, *FAST, port=port) as second:
            started = time.monotonic()
            discovered = timed(
                lambda: all(second.robot(r) is not None for r in robots), 30, "robots discovered"
            )
            complete = timed(lambda: whole(second, robots, 10), 30, "the whole fleet") + discovered
            assert lost(second) == 0
        healthy_to_whole = time.monotonic() - started
    print(
        f"\nexporter restart (SIGKILL): healthy → all discovered {discovered:.2f}s → whole {complete:.2f}s "
        f"(publish period {period:g}s)"
    )
    assert complete - discovered <= period + 0.5
    assert healthy_to_whole < 30


# --- A robot behind a veth link ---

PUBLISHER = """
import sys
from overseer.simulator.publisher import FleetSimulator, SimulatorSettings
from overseer.sources.dds.cyclone_config import configure_domain


domain = int(sys.argv[1])
configure_domain(domain, sys.argv[2])
settings = SimulatorSettings(robots=1, components=10, rate=4, domain=domain, namespace_prefix="remote")
FleetSimulator(settings).run()
"""


def cyclone_over(interface: str, peer: str) -> str:
    """A Cyclone DDS configuration on one interface with one unicast peer, re-announcing every second.

    After a cut longer than the lease (10 s), the two sides find each other again at the next
    announcement: Cyclone's default interval is 30 s, so the link test shortens it.
    """
    return (
        '<CycloneDDS><Domain id="any">'
        f'<General><Interfaces><NetworkInterface name="{interface}"/></Interfaces>'
        "<AllowMulticast>false</AllowMulticast></General>"
        "<Discovery><ParticipantIndex>auto</ParticipantIndex>"
        f'<Peers><Peer address="{peer}"/></Peers><SPDPInterval>1s</SPDPInterval></Discovery>'
        "</Domain></CycloneDDS>"
    )


@contextmanager
def exporter_over(tmp_path: Path, link: VethNamespace, domain: int) -> Iterator[Exporter]:
    """`overseer run` talking DDS over the host end of `link`, HTTP on loopback."""
    port = free_port()
    args = [
        *overseer_command(),
        "run",
        f"--web.listen-address=127.0.0.1:{port}",
        f"--dds.domain={domain}",
        f"--dds.cyclonedds-uri={cyclone_over(link.outside, link.inside_address)}",
        *FAST,
    ]
    log_path = tmp_path / "exporter-veth.log"
    exporter = Exporter(spawn(args, log_path, cwd=tmp_path), log_path, f"http://127.0.0.1:{port}")
    try:
        wait_until_healthy(exporter, 30)
        yield exporter
    finally:
        exporter.stop()


@contextmanager
def publisher_inside(tmp_path: Path, link: VethNamespace, domain: int) -> Iterator[RunningProcess]:
    """The simulated robot `remote1`, publishing from inside the namespace over its end of `link`."""
    config = cyclone_over(link.inside, link.outside_address)
    args = link.command([sys.executable, "-c", PUBLISHER, str(domain), config])
    log_path = tmp_path / "publisher-netns.log"
    publisher = RunningProcess(spawn(args, log_path), log_path)
    try:
        yield publisher
    finally:
        publisher.stop()


@pytest.mark.parametrize("cut_seconds", [5.0, 15.0], ids=["within-the-lease", "past-the-lease"])
def test_robot_behind_a_cut_link_is_down_while_cut_and_back_after_without_restarts(
    tmp_path: Path, dds_domain: int, cut_seconds: float
) -> None:
    with (
        veth_namespace() as link,
        exporter_over(tmp_path, link, dds_domain) as exporter,
        publisher_inside(tmp_path, link, dds_domain) as publisher,
    ):
        pids = (exporter.process.pid, publisher.process.pid)
        wait_for(
            lambda: whole(exporter, ["remote1"], 10), 60, message=f"remote1 over the veth\n{publisher.log()}"
        )
        link.cut()
        try:
            down = timed(lambda: down_and_stale(exporter, "remote1"), ROBOT_TIMEOUT + 5, "remote1 down")
            deadline = time.monotonic() + cut_seconds - down
            while time.monotonic() < deadline:  # it stays down, and the exporter keeps serving, while cut
                assert down_and_stale(exporter, "remote1")
                time.sleep(0.5)
        finally:
            link.restore()
        back = timed(lambda: whole(exporter, ["remote1"], 10), 30, "remote1 back")
        assert (exporter.process.pid, publisher.process.pid) == pids
        assert exporter.process.poll() is None and publisher.process.poll() is None
        assert lost(exporter) == 0
    print(
        f"\nlink cut for {cut_seconds:g}s: down and STALE {down:.1f}s after the cut, "
        f"whole {back:.1f}s after the restore"
    )
    assert down <= ROBOT_TIMEOUT + 1.5


# --- Prometheus and Alertmanager down ---


def ingest_rate(exporter: Exporter, seconds: float, robots: list[str]) -> float:
    """Messages received per second over `seconds`, failing if any robot goes down or STALE meanwhile."""

    def received() -> float:
        for line in exporter.get("/metrics").decode().splitlines():
            if line.startswith("overseer_messages_total{") and 'result="received"' in line:
                return float(line.rsplit(" ", 1)[1])
        raise AssertionError("no received counter")

    first, started = received(), time.monotonic()
    while time.monotonic() - started < seconds:
        robots_now = exporter.get_json("/api/v1/robots")["robots"]
        assert all(r["up"] and r["counts"]["stale"] == 0 for r in robots_now), robots_now
        assert sorted(r["robot"] for r in robots_now) == sorted(robots)
        time.sleep(0.25)
    return (received() - first) / (time.monotonic() - started)


def test_prometheus_frozen_or_killed_and_alertmanager_killed_leave_ingest_untouched(
    tmp_path: Path, dds_domain: int
) -> None:
    robots, rate = [f"robot{i}" for i in range(1, 11)], 5.0
    silent = {"route": {"receiver": "nobody"}, "receivers": [{"name": "nobody"}]}
    with (
        running_exporter(tmp_path, dds_domain) as exporter,
        running_simulator(tmp_path, dds_domain, "--robots=10", f"--rate={rate:g}"),
        running_alertmanager(tmp_path, silent) as alertmanager,
        running_prometheus(
            tmp_path, shipped_config("prometheus-fast.yml", [exporter.url], alertmanager.url, interval="1s")
        ) as prometheus,
    ):
        wait_for(lambda: prometheus.query('up{job="overseer"} == 1'), 30, message="Prometheus scraping")

        wait_for(lambda: len(exporter.get_json("/api/v1/robots")["robots"]) == 10, 30, message="the fleet")
        expected = len(robots) * rate
        rates = {"all running": ingest_rate(exporter, 5, robots)}
        alertmanager.process.kill()
        prometheus.process.send_signal(signal.SIGSTOP)  # frozen with its connections open
        try:
            rates["Prometheus frozen, Alertmanager killed"] = ingest_rate(exporter, 12, robots)
        finally:
            prometheus.process.send_signal(signal.SIGCONT)
        fresh = 'up{job="overseer"} == 1 and time() - timestamp(up{job="overseer"}) < 3'
        wait_for(lambda: prometheus.query(fresh), 30, message="Prometheus scraping again")
        prometheus.process.kill()
        prometheus.process.wait()
        rates["Prometheus killed"] = ingest_rate(exporter, 5, robots)
        assert lost(exporter) == 0
    print(
        "\ningest (messages/s, "
        + f"{expected:g} published): "
        + ", ".join(f"{k} {v:.1f}" for k, v in rates.items())
    )
    assert all(value >= 0.95 * expected for value in rates.values()), rates


def test_the_namespace_and_its_veth_pair_are_removed_after_the_test() -> None:
    with veth_namespace() as link:
        pass
    namespaces = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True, check=True).stdout
    links = subprocess.run(["ip", "-o", "link"], capture_output=True, text=True, check=True).stdout
    assert link.name not in namespaces and link.outside not in links
