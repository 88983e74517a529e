"""DDS discovery by unicast peers, across a link that carries no multicast (needs root).

How it is isolated: each test makes a network namespace joined to the host by a veth pair
(`testbed.netns.veth_namespace(multicast=False)`) and takes the MULTICAST flag off both ends of the pair
and off the namespace's loopback. The simulated robots run inside the namespace with Cyclone's default
configuration, as on a second machine of a network without multicast; nothing tells them about the
exporter unless a test says so. The exporter runs on the host, its DDS held to the host end of the pair by
an operator's `--dds.cyclonedds-uri` that names that interface (as on a server with several interfaces):
not the loopback-only configuration, whose peer 127.0.0.1 would find anything on this machine. Cyclone
sees no multicast-capable interface on either side, so the only way across is unicast to a named peer.
(The flag off on loopback alone would not do: Cyclone still multicasts over `lo` and Linux delivers it,
so exporter and robots sharing one namespace would find each other; hence two hosts joined by a veth.)
The Fast DDS publisher of testbed/fastdds stands in for a robot on rmw_fastrtps_cpp. Each test has a DDS
domain of its own, and the namespace and its veth pair are deleted when it ends.
"""

from __future__ import annotations

import subprocess
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from overseer.levels import Level
from overseer.simulator.design import aggregated_statuses, initial_levels, leaf_components
from testbed.fastdds_build import build_fastdds_publisher
from testbed.netns import VethNamespace, veth_namespace
from testbed.paths import REPO
from testbed.ports import free_port
from testbed.processes import Exporter, RunningProcess, overseer_command, spawn, wait_for, wait_until_healthy

pytestmark = pytest.mark.servers  # every test here starts real servers or middleware


COMPONENTS = 10
FASTDDS_BUILD_DIR = REPO / ".cache" / "fastdds-build"
QUIET_WINDOW = 8.0  # seconds in which nothing may be heard without peers
DISCOVERY_TIMEOUT = 30.0


def interface_only(interface: str, discovery: str = "") -> str:
    """An operator's Cyclone configuration that only picks the DDS interface (plus `discovery` settings)."""
    return (
        '<CycloneDDS><Domain id="any">'
        f'<General><Interfaces><NetworkInterface name="{interface}"/></Interfaces></General>'
        f"{f'<Discovery>{discovery}</Discovery>' if discovery else ''}"
        "</Domain></CycloneDDS>"
    )


@contextmanager
def exporter_on_host(
    tmp_path: Path, link: VethNamespace, domain: int, *extra: str, discovery: str = ""
) -> Iterator[Exporter]:
    """`overseer run` on the host, DDS on the host end of `link` only, HTTP on loopback."""
    port = free_port()
    args = [
        *overseer_command(),
        "run",
        f"--web.listen-address=127.0.0.1:{port}",
        f"--dds.domain={domain}",
        f"--dds.cyclonedds-uri={interface_only(link.outside, discovery)}",
        *extra,
    ]
    log_path = tmp_path / f"exporter-{port}.log"
    exporter = Exporter(
        spawn(args, log_path, env={"CYCLONEDDS_URI": ""}), log_path, f"http://127.0.0.1:{port}"
    )
    try:
        wait_until_healthy(exporter, 30)
        yield exporter
    finally:
        exporter.stop()


@contextmanager
def robot_process(
    tmp_path: Path, link: VethNamespace, domain: int, prefix: str, *extra: str, cyclonedds_uri: str = ""
) -> Iterator[RunningProcess]:
    """One `overseer simulate` process inside the namespace: robot `<prefix>1`, Cyclone's defaults."""
    args = link.command(
        [
            *overseer_command(),
            "simulate",
            f"--domain={domain}",
            "--robots=1",
            f"--components={COMPONENTS}",
            f"--namespace-prefix={prefix}",
            "--rate=4",
            *extra,
        ]
    )
    log_path = tmp_path / f"robot-{prefix}.log"
    robot = RunningProcess(spawn(args, log_path, env={"CYCLONEDDS_URI": cyclonedds_uri}), log_path)
    try:
        yield robot
    finally:
        robot.stop()


def discovery_port(domain: int, index: int) -> int:
    """The UDP port a DDS participant with participant index `index` on `domain` listens on for discovery."""
    return 7400 + 250 * domain + 10 + 2 * index


def wait_for_participants(link: VethNamespace, domain: int, indices: list[int]) -> None:
    """Wait until DDS participants inside the namespace listen on the discovery ports of `indices`.

    The exporter probes a peer as it starts and then every 30 s, so the robots must be up before it.
    """

    def listening() -> bool:
        for index in indices:
            port = f"sport = :{discovery_port(domain, index)}"
            ss = subprocess.run(
                link.command(["ss", "-Hlun", port]), capture_output=True, text=True, check=True
            )
            if not ss.stdout.strip():
                return False
        return True

    wait_for(listening, 30, message=f"DDS participants on indices {indices} in {link.name}")


def expected_levels() -> dict[str, float]:
    """Component → level as every simulated robot publishes it (one WARN and one ERROR leaf)."""
    leaves = leaf_components(COMPONENTS)
    statuses = aggregated_statuses(leaves, initial_levels(leaves, 1, 1), set())
    return {status.name: float(Level(status.level)) for status in statuses}


def levels_on_metrics(exporter: Exporter, robot: str) -> dict[str, float]:
    """Component → `ros_diagnostics_level` of one robot, read from /metrics."""
    levels: dict[str, float] = {}
    for labels, value in exporter.samples().get("ros_diagnostics_level", {}).items():
        label = dict(labels)
        if label["robot"] == robot:
            levels[label["component"]] = value
    return levels


def heard(exporter: Exporter, robot: str) -> bool:
    """The robot's every component is on /metrics at the level the simulator publishes."""
    return levels_on_metrics(exporter, robot) == expected_levels()


def robots_known(exporter: Exporter) -> list[str]:
    """The names /api/v1/robots lists."""
    return [robot["robot"] for robot in exporter.get_json("/api/v1/robots")["robots"]]


def assert_nothing_heard(exporter: Exporter, robots: list[RunningProcess], seconds: float) -> None:
    """For `seconds`, the exporter knows no robot while every robot process keeps publishing."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        assert robots_known(exporter) == [], exporter.log()
        time.sleep(0.5)
    for robot in robots:
        assert robot.process.poll() is None, robot.log()


def assert_multicast_off(link: VethNamespace) -> None:
    """Neither end of the pair, nor the namespace's loopback, carries the MULTICAST flag."""
    flags = [
        subprocess.run(command, capture_output=True, text=True, check=True).stdout.split(">")[0]
        for command in (
            ["ip", "link", "show", link.outside],
            link.command(["ip", "link", "show", link.inside]),
            link.command(["ip", "link", "show", "lo"]),
        )
    ]
    assert all("MULTICAST" not in flag.split("<")[1].split(",") for flag in flags), flags


@contextmanager
def two_robot_processes(
    tmp_path: Path, link: VethNamespace, domain: int, beta_uri: str = "", beta_index: int = 1
) -> Iterator[tuple[RunningProcess, RunningProcess]]:
    """Robots alpha1 and beta1 in two processes inside the namespace, up and listening when yielded."""
    with (
        robot_process(tmp_path, link, domain, "alpha") as alpha,
        robot_process(tmp_path, link, domain, "beta", cyclonedds_uri=beta_uri) as beta,
    ):
        wait_for_participants(link, domain, [0, beta_index])
        yield alpha, beta


def test_without_peers_no_robot_is_heard_across_a_link_without_multicast(
    tmp_path: Path, dds_domain: int
) -> None:
    with (
        veth_namespace(multicast=False) as link,
        two_robot_processes(tmp_path, link, dds_domain) as robots,
        exporter_on_host(tmp_path, link, dds_domain) as exporter,
    ):
        assert_multicast_off(link)
        assert_nothing_heard(exporter, list(robots), QUIET_WINDOW)


def test_with_a_peer_the_robots_of_two_processes_on_that_host_are_heard(
    tmp_path: Path, dds_domain: int
) -> None:
    with (
        veth_namespace(multicast=False) as link,
        two_robot_processes(tmp_path, link, dds_domain),
        exporter_on_host(tmp_path, link, dds_domain, f"--dds.peer={link.inside_address}") as exporter,
    ):
        assert_multicast_off(link)
        for name in ("alpha1", "beta1"):
            wait_for(
                lambda name=name: heard(exporter, name),
                DISCOVERY_TIMEOUT,
                message=f"{name} on /metrics ({exporter.log_path})",
            )
        assert sorted(robots_known(exporter)) == ["alpha1", "beta1"]


def test_a_robot_that_names_the_exporter_as_its_peer_is_heard_by_an_exporter_without_peers(
    tmp_path: Path, dds_domain: int
) -> None:
    with (
        veth_namespace(multicast=False) as link,
        exporter_on_host(tmp_path, link, dds_domain) as exporter,
        robot_process(tmp_path, link, dds_domain, "alpha", f"--dds.peer={link.outside_address}") as alpha,
    ):
        wait_for(
            lambda: heard(exporter, "alpha1"),
            DISCOVERY_TIMEOUT,
            message=f"alpha1 on /metrics ({alpha.log_path}, {exporter.log_path})",
        )


def test_max_participant_index_bounds_the_processes_probed_on_a_peer(tmp_path: Path, dds_domain: int) -> None:
    """With indices 0..1 probed, the robot process on index 0 is heard and the one fixed on index 2 is not."""
    on_index_2 = (
        '<CycloneDDS><Domain id="any"><Discovery><ParticipantIndex>2</ParticipantIndex></Discovery>'
        "</Domain></CycloneDDS>"
    )
    with (
        veth_namespace(multicast=False) as link,
        two_robot_processes(tmp_path, link, dds_domain, beta_uri=on_index_2, beta_index=2) as robots,
        exporter_on_host(
            tmp_path,
            link,
            dds_domain,
            f"--dds.peer={link.inside_address}",
            "--dds.max-participant-index=1",
            "--ingest.workers=1",  # each worker is a participant of its own: two would need both indices
        ) as exporter,
    ):
        wait_for(
            lambda: heard(exporter, "alpha1"), DISCOVERY_TIMEOUT, message=f"alpha1 ({exporter.log_path})"
        )
        deadline = time.monotonic() + QUIET_WINDOW
        while time.monotonic() < deadline:
            assert robots_known(exporter) == ["alpha1"]
            time.sleep(0.5)
        assert all(robot.process.poll() is None for robot in robots)


def test_a_robot_that_starts_after_cyclones_peer_timeout_is_still_found(
    tmp_path: Path, dds_domain: int
) -> None:
    """Cyclone stops probing a peer that has not answered within InitialLocatorPruneDelay; ours never stop.

    The operator's configuration shortens that delay to 1 s (30 s by default) and the probe interval to
    1 s, and the robot starts 4 s after the exporter, as robots boot after their exporter.
    """
    fast = "<InitialLocatorPruneDelay>1s</InitialLocatorPruneDelay><SPDPInterval>1s</SPDPInterval>"
    with (
        veth_namespace(multicast=False) as link,
        exporter_on_host(
            tmp_path, link, dds_domain, f"--dds.peer={link.inside_address}", discovery=fast
        ) as exporter,
    ):
        time.sleep(4)
        with robot_process(tmp_path, link, dds_domain, "alpha") as alpha:
            wait_for(
                lambda: heard(exporter, "alpha1"),
                DISCOVERY_TIMEOUT,
                message=f"alpha1 on /metrics ({alpha.log_path}, {exporter.log_path})",
            )


def test_with_a_peer_a_fast_dds_robot_is_heard(tmp_path: Path, dds_domain: int) -> None:
    """A Fast DDS process (as rmw_fastrtps_cpp) takes participant id 0, whose port the peer probe reaches."""
    publisher = build_fastdds_publisher(FASTDDS_BUILD_DIR)
    args = [
        str(publisher),
        "--domain",
        str(dds_domain),
        "--topic",
        "rt/fastbot/diagnostics_agg",
        "--rate",
        "4",
    ]
    args += ["--status", "2|/Laser|No scans|laser1|", "--status", "1|/Power|Low charge|bms|voltage=11.1"]
    with veth_namespace(multicast=False) as link:
        args += ["--interface", link.inside_address]
        robot = RunningProcess(spawn(link.command(args), tmp_path / "fastdds.log"), tmp_path / "fastdds.log")
        try:
            wait_for_participants(link, dds_domain, [0])
            with exporter_on_host(
                tmp_path, link, dds_domain, f"--dds.peer={link.inside_address}"
            ) as exporter:
                wait_for(
                    lambda: levels_on_metrics(exporter, "fastbot") == {"/Laser": 2.0, "/Power": 1.0},
                    DISCOVERY_TIMEOUT,
                    message=f"fastbot on /metrics ({robot.log_path}, {exporter.log_path})",
                )
        finally:
            robot.stop()
