"""Ingest workers end to end: a real exporter with several worker processes, real DDS and Zenoh robots.

Every process runs on loopback: DDS with the loopback-only configuration, Zenoh through a router of the
test's own (a Python session in router mode). Workers are found as the exporter's children started by
`overseer.fleet.workers.launch`, and the exporter has no other child.
"""

from __future__ import annotations

import os
import signal
import time
from dataclasses import replace
from pathlib import Path

import pytest

from bench.common import process_tree
from overseer.config import Config
from overseer.config.dds import DdsConfig, DomainConfig
from overseer.config.events import EventsConfig
from overseer.config.ingest import IngestConfig
from overseer.fleet.pooled import PooledFleet
from overseer.fleet.workers import pool as pool_module
from overseer.fleet.workers.launch import CHILD_MARKER, start_child
from overseer.fleet.workers.pool import WorkersUnavailable
from overseer.model.shard import Shard
from testbed.nagios import run_check
from testbed.processes import Exporter, running_exporter, running_simulator, wait_for
from testbed.zenoh import exporter_args, running_router, simulator_args

pytestmark = pytest.mark.servers  # every test here starts real servers or middleware


ROBOTS = 12
COMPONENTS = 5
SERIES_PER_ROBOT = 2 * COMPONENTS  # the simulated leaves and the aggregator's group statuses


def worker_pids(exporter: Exporter) -> list[int]:
    """The pids of the exporter's ingest workers (started by the workers' launcher)."""
    return [pid for pid, command in exporter_descendants(exporter) if CHILD_MARKER.encode() in command]


def exporter_descendants(exporter: Exporter) -> list[tuple[int, bytes]]:
    """Every process descending from the exporter, with its command line."""
    descendants = []
    for pid in process_tree(exporter.process.pid)[1:]:
        try:
            with open(f"/proc/{pid}/cmdline", "rb") as cmdline:
                descendants.append((pid, cmdline.read()))
        except OSError:
            continue  # it ended meanwhile
    return descendants


def robots_served(exporter: Exporter) -> list[str]:
    """The robot label of every ros_diagnostics_robot_up sample, duplicates kept."""
    text = exporter.get("/metrics").decode()
    return [
        line.split('robot="', 1)[1].split('"', 1)[0]
        for line in text.splitlines()
        if line.startswith("ros_diagnostics_robot_up{")
    ]


def every_robot_once(exporter: Exporter, expected: set[str]) -> bool:
    """True when /metrics serves each expected robot exactly once, up, with all its components."""
    served = robots_served(exporter)
    if sorted(served) != sorted(expected):
        return False
    samples = exporter.samples()
    ups = samples["ros_diagnostics_robot_up"]
    levels = samples["ros_diagnostics_level"]
    return all(value == 1.0 for value in ups.values()) and len(levels) == len(expected) * SERIES_PER_ROBOT


def worker_metric(exporter: Exporter, name: str, worker: int) -> float | None:
    return exporter.samples().get(name, {}).get((("worker", str(worker)),))


def test_workers_serve_every_dds_robot_once_through_metrics_api_and_check(
    tmp_path: Path, dds_domain: int
) -> None:
    expected = {f"robot{index}" for index in range(1, ROBOTS + 1)}
    with (
        running_exporter(tmp_path, dds_domain, "--ingest.workers=3") as exporter,
        running_simulator(tmp_path, dds_domain, f"--robots={ROBOTS}", f"--components={COMPONENTS}"),
    ):
        wait_for(lambda: every_robot_once(exporter, expected), 30, message="every robot once")
        assert len(worker_pids(exporter)) == 3
        # No process beside them: `multiprocessing`'s resource tracker held 13 MB for nothing to track.
        assert sorted(pid for pid, _ in exporter_descendants(exporter)) == sorted(worker_pids(exporter))
        samples = exporter.samples()
        assert samples["overseer_ingest_workers"][()] == 3.0
        assert all(worker_metric(exporter, "overseer_ingest_worker_up", index) == 1.0 for index in range(3))
        # The workers' counters are added up once: received grows by ~ROBOTS a second, from all of them.
        received = samples["overseer_messages_total"][(("result", "received"), ("transport", "dds"))]
        assert received >= ROBOTS
        assert len(samples["overseer_build_info"]) == 1
        # The maintenance series name every worker's robots (from their names, not their documents).
        maintenance = samples["ros_diagnostics_robot_maintenance"]
        assert sorted(dict(labels)["robot"] for labels in maintenance) == sorted(expected)
        assert set(maintenance.values()) == {0.0}
        # Each worker followed only its own robots: no robot is followed twice.
        following = [line for line in exporter.log().splitlines() if "following robot" in line]
        assert len(following) == ROBOTS
        robots = exporter.get_json("/api/v1/robots")["robots"]
        assert [robot["robot"] for robot in robots] == sorted(expected)
        assert all(robot["components"] == SERIES_PER_ROBOT for robot in robots)
        errors = exporter.get_json("/api/v1/components?level=ERROR&limit=1000")
        assert {item["robot"] for item in errors["robots"]} == expected  # every robot has an ERROR leaf
        assert errors["total"] == sum(item["matches"] for item in errors["robots"])
        for robot in ("robot1", "robot2", "robot7"):
            result = run_check("--url", exporter.url, "-r", robot)
            assert result.state == 2, result.output
            assert result.output.startswith(f"CRITICAL - {robot}: /Laser/Laser1 (No scans received)"), (
                result.output
            )
            assert "CRITICAL sensor(s) list:" in result.output
        assert exporter.robot("robot99") is None


def test_the_robot_cap_holds_for_the_fleet_whichever_worker_its_robots_hash_to(
    tmp_path: Path, dds_domain: int
) -> None:
    config = tmp_path / "overseer.yml"
    config.write_text("fleet:\n  max_robots: 3\n")
    crowded = {"robot1", "robot2", "robot3"}
    assert {Shard().worker_of(robot, 2) for robot in crowded} == {0}  # a share of the cap would keep two
    with running_exporter(tmp_path, dds_domain, "--ingest.workers=2", f"--config.file={config}") as exporter:
        with running_simulator(tmp_path, dds_domain, "--robots=3", f"--components={COMPONENTS}"):
            wait_for(lambda: every_robot_once(exporter, crowded), 30, message="three robots in one worker")
        # a fourth robot, of the other worker, finds the fleet's cap full
        assert Shard().worker_of("extra1", 2) == 1
        extra = ("--robots=1", f"--components={COMPONENTS}", "--namespace-prefix=extra")
        with running_simulator(tmp_path, dds_domain, *extra):
            refused = (("reason", "robot_limit"),)
            wait_for(
                lambda: exporter.samples()["overseer_statuses_dropped_total"].get(refused),
                30,
                message="the fourth robot refused and counted",
            )
            assert sorted(robots_served(exporter)) == sorted(crowded)


def test_a_killed_worker_is_restarted_and_its_robots_relearned(tmp_path: Path, dds_domain: int) -> None:
    expected = {f"robot{index}" for index in range(1, ROBOTS + 1)}
    with (
        running_exporter(tmp_path, dds_domain, "--ingest.workers=2", "--fleet.robot-timeout=60s") as exporter,
        running_simulator(tmp_path, dds_domain, f"--robots={ROBOTS}", f"--components={COMPONENTS}"),
    ):
        wait_for(lambda: every_robot_once(exporter, expected), 30, message="every robot once")
        received = ("overseer_messages_total", (("result", "received"), ("transport", "dds")))
        received_before = exporter.samples()[received[0]][received[1]]
        before = set(worker_pids(exporter))
        victim = min(before)
        os.kill(victim, signal.SIGKILL)
        killed_at = time.monotonic()
        wait_for(lambda: len(set(worker_pids(exporter)) - before) == 1, 10, message="a new worker process")
        wait_for(lambda: every_robot_once(exporter, expected), 10, message="every robot relearned")
        relearned_after = time.monotonic() - killed_at
        assert relearned_after < 10
        restarts = [
            worker_metric(exporter, "overseer_ingest_worker_restarts_total", index) for index in range(2)
        ]
        assert sorted(restarts) == [0.0, 1.0]  # type: ignore[type-var]
        assert all(worker_metric(exporter, "overseer_ingest_worker_up", index) == 1.0 for index in range(2))
        assert "exited with code -9; restarting it" in exporter.log()
        # The exporter-wide counters carry the dead worker's counts: Prometheus sees no reset.
        assert exporter.samples()[received[0]][received[1]] > received_before
        last_workers = worker_pids(exporter)
    assert exporter.process.returncode == 0
    # Stopping the exporter stops its workers too.
    wait_for(lambda: not any(_alive(pid) for pid in last_workers), 10, message="the workers gone")


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def test_workers_share_zenoh_robots_and_a_killed_one_relearns_them(tmp_path: Path) -> None:
    expected = {f"site/robot{index}" for index in range(1, ROBOTS + 1)}
    with (
        running_router(tmp_path) as port,
        running_exporter(tmp_path, None, *exporter_args(port, "--ingest.workers=2")) as exporter,
        running_simulator(
            tmp_path,
            0,
            *simulator_args(
                port, f"--robots={ROBOTS}", f"--components={COMPONENTS}", "--namespace-prefix=site/robot"
            ),
        ),
    ):
        wait_for(lambda: every_robot_once(exporter, expected), 30, message="every Zenoh robot once")
        samples = exporter.samples()
        assert samples["overseer_messages_total"][(("result", "received"), ("transport", "zenoh"))] >= ROBOTS
        # Every worker hears every key and keeps only its own robots' samples: none decoded twice.
        assert samples["overseer_messages_total"].get((("result", "dropped"), ("transport", "zenoh"))) == 0.0
        before = set(worker_pids(exporter))
        os.kill(max(before), signal.SIGKILL)
        wait_for(lambda: len(set(worker_pids(exporter)) - before) == 1, 10, message="a new worker process")
        wait_for(lambda: every_robot_once(exporter, expected), 10, message="every Zenoh robot relearned")
        restarts = [
            worker_metric(exporter, "overseer_ingest_worker_restarts_total", index) for index in range(2)
        ]
        assert sorted(restarts) == [0.0, 1.0]  # type: ignore[type-var]


def started_pool_of_two(dds_domain: int) -> PooledFleet:
    """An in-process pool of two real workers, on a DDS domain of their own, following no robot yet."""
    config = replace(
        Config(),
        dds=replace(DdsConfig(), loopback_only=True, domains=(DomainConfig(dds_domain),)),
        events=EventsConfig(enabled=False),
        ingest=IngestConfig(workers=2),
    )
    fleet = PooledFleet(config)
    fleet.start()
    return fleet


def test_a_hung_worker_is_killed_and_restarted_while_the_others_answer(
    dds_domain: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """An in-process pool of real worker processes (DDS on a domain of its own, no robots); one is stopped."""
    monkeypatch.setattr(pool_module, "ANSWER_TIMEOUT_SECONDS", 2.0)
    fleet = started_pool_of_two(dds_domain)
    pool = fleet.pool
    try:
        assert len(pool.ask_all("robots")) == 2
        hung = pool.pid(1)
        assert hung is not None
        os.kill(hung, signal.SIGSTOP)
        started = time.monotonic()
        answers = pool.ask_all("robots")
        assert len(answers) == 1  # the live worker answered; the hung one was given up on
        assert time.monotonic() - started < 10
        wait_for(lambda: pool.restarts[1] == 1 and pool.up(1), 20, message="the hung worker restarted")
        assert pool.pid(1) != hung
        assert len(pool.ask_all("robots")) == 2
        assert pool.restarts[0] == 0
        # Stopped again: the API answers 503 for its robots, and the Icinga 2 push gets no partial fleet.
        owned_by_1 = next(f"robot{i}" for i in range(100) if Shard().for_worker(1, 2).owns(f"robot{i}"))
        os.kill(pool.pid(1) or 0, signal.SIGSTOP)
        with pytest.raises(WorkersUnavailable, match=f"ingest worker 1, which follows '{owned_by_1}'"):
            fleet.robot_document(owned_by_1)
        wait_for(lambda: pool.restarts[1] == 2 and pool.up(1), 20, message="restarted again")
        os.kill(pool.pid(1) or 0, signal.SIGSTOP)
        with pytest.raises(WorkersUnavailable, match=r"ingest worker \[1\] did not answer"):
            fleet.robot_digests()  # what the push reads each look
        with pytest.raises(WorkersUnavailable, match=r"ingest worker \[1\] did not answer"):
            fleet.robots_snapshot([owned_by_1])
        wait_for(lambda: pool.restarts[1] == 3 and pool.up(1), 20, message="restarted a third time")
        assert fleet.robot_digests() == {} and fleet.robots_snapshot(["robot1"]).robots == ()
        fleet.prepare_exposition()  # every worker renders ahead of a scrape
        # A render ahead of a scrape that a worker could not do is a failure (counted), not done.
        os.kill(pool.pid(1) or 0, signal.SIGSTOP)
        with pytest.raises(WorkersUnavailable, match=r"ingest worker \[1\] did not answer"):
            fleet.prepare_exposition()
        wait_for(lambda: pool.restarts[1] == 4 and pool.up(1), 20, message="restarted a fourth time")
    finally:
        fleet.stop()


def test_a_worker_whose_process_cannot_be_made_is_tried_again_and_the_supervisor_goes_on(
    dds_domain: int, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    """An in-process pool of real workers; the first restart finds no room for a process (as after an OOM)."""
    fleet = started_pool_of_two(dds_domain)
    pool = fleet.pool
    made: list[int] = []

    def start_child_failing_twice(*args: object) -> object:
        made.append(1)
        if len(made) == 1:
            raise OSError(12, "Cannot allocate memory")
        if len(made) == 2:
            raise ValueError("a failure no one foresaw")
        return start_child(*args)  # type: ignore[arg-type]

    monkeypatch.setattr(pool_module, "start_child", start_child_failing_twice)
    try:
        dead = pool.pid(0)
        os.kill(dead or 0, signal.SIGKILL)
        wait_for(lambda: pool.up(0) and pool.pid(0) != dead, 20, message="the worker made at the third try")
        assert len(made) == 3
        assert "ingest worker 0 could not be started: [Errno 12] Cannot allocate memory" in caplog.text
        assert "ingest worker 0 could not be restarted; trying again" in caplog.text
        assert caplog.text.count(f"(pid {dead}) exited") == 1  # its death told once, not at each try
        assert len(pool.ask_all("robots")) == 2
        os.kill(pool.pid(0) or 0, signal.SIGKILL)  # the supervisor still watches
        wait_for(lambda: pool.restarts[0] == 4 and pool.up(0), 20, message="restarted once more")
    finally:
        fleet.stop()


def test_a_stop_sent_to_the_whole_process_group_restarts_no_worker(tmp_path: Path, dds_domain: int) -> None:
    """As systemd stops a service (SIGTERM to every process of its cgroup): workers wait for the exporter."""
    with running_exporter(tmp_path, dds_domain, "--ingest.workers=2") as exporter:
        workers = worker_pids(exporter)
        assert len(workers) == 2
        os.killpg(exporter.process.pid, signal.SIGTERM)  # the exporter leads its own session and group
        assert exporter.process.wait(20) == 0
    wait_for(lambda: not any(_alive(pid) for pid in workers), 10, message="the workers gone")
    assert "restarting it" not in exporter.log()
    assert "restarted" not in exporter.log()
