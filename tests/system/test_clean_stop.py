"""`overseer run` stops cleanly on SIGTERM and SIGINT from every source, and at once on a second signal.

Each case runs a real exporter following a real robot (DDS simulator, rclpy robot, Zenoh router and
simulator, ROS 1 master and rospy publisher, DDS with ingest workers), stops it with a signal and checks
the exit status, that it said it stopped, and that the event database was closed: SQLite removes its
write-ahead log and shared-memory files when the last connection closes after a checkpoint.
"""

from __future__ import annotations

import signal
import socket
import subprocess
import time
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path

import pytest

from testbed.processes import Exporter, running_exporter, running_simulator, wait_for
from testbed.ros1 import running_master, running_publisher
from testbed.ros2 import ros2_environment, running_robots
from testbed.zenoh import exporter_args, running_router, simulator_args

pytestmark = pytest.mark.servers

SOURCES = ("dds", "ros2", "zenoh", "ros1", "dds-workers")
DATABASE = "overseer-events.db"


@contextmanager
def exporter_with_a_robot(tmp_path: Path, domain: int, source: str) -> Iterator[tuple[Exporter, str]]:
    """An exporter of `source` following one live robot; yields it and the robot's name."""
    with ExitStack() as stack:
        if source in ("dds", "dds-workers"):
            workers = "--ingest.workers=2" if source == "dds-workers" else "--ingest.workers=1"
            exporter = stack.enter_context(running_exporter(tmp_path, domain, workers))
            stack.enter_context(running_simulator(tmp_path, domain, "--robots=2"))
            robot = "robot1"
        elif source == "ros2":
            exporter = stack.enter_context(
                running_exporter(
                    tmp_path,
                    None,
                    "--ros2",
                    "--ingest.workers=1",
                    env=ros2_environment(domain),
                    loopback_flag=False,
                )
            )
            stack.enter_context(running_robots(tmp_path, domain, ("--namespace", "alpha")))
            robot = "alpha"
        elif source == "zenoh":
            port = stack.enter_context(running_router(tmp_path))
            exporter = stack.enter_context(
                running_exporter(tmp_path, None, *exporter_args(port), loopback_flag=False)
            )
            stack.enter_context(running_simulator(tmp_path, 0, *simulator_args(port, "--robots=1")))
            robot = "robot1"
        else:
            master = stack.enter_context(running_master(tmp_path))
            exporter = stack.enter_context(
                running_exporter(tmp_path, None, "--dds.disabled", f"--ros1.robot=bot={master.uri}")
            )
            stack.enter_context(running_publisher(tmp_path, master, "driver", ["0:/Power:ok"]))
            robot = "bot"
        wait_for(lambda: (exporter.robot(robot) or {}).get("up"), 45, message=f"{robot} up over {source}")
        yield exporter, robot


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
@pytest.mark.parametrize("source", SOURCES)
def test_a_signal_stops_the_exporter_with_status_0_and_every_output_closed(
    tmp_path: Path, dds_domain: int, source: str, sig: signal.Signals
) -> None:
    with exporter_with_a_robot(tmp_path, dds_domain, source) as (exporter, _):
        assert (tmp_path / DATABASE).exists()
        started = time.monotonic()
        status = exporter.stop(sig, timeout=30)
        took = time.monotonic() - started
    log = exporter.log()
    assert status == 0, log[-3000:]
    assert took < 15, f"stopping took {took:.1f}s"
    assert "stopping" in log and "stopped" in log.splitlines()[-1], log[-2000:]
    assert "Traceback" not in log, log[-3000:]
    assert not (tmp_path / f"{DATABASE}-wal").exists() and not (tmp_path / f"{DATABASE}-shm").exists()


@contextmanager
def silent_server() -> Iterator[int]:
    """A TCP port that accepts connections and never answers (a hung Icinga 2)."""
    with socket.create_server(("127.0.0.1", 0), backlog=16) as server:
        yield server.getsockname()[1]


def test_a_second_signal_during_a_slow_stop_ends_the_exporter_at_once(
    tmp_path: Path, dds_domain: int
) -> None:
    password = tmp_path / "password"
    password.write_text("secret\n", encoding="utf-8")
    ca = tmp_path / "ca.crt"
    key = tmp_path / "ca.key"
    command = ["openssl", "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "1", "-subj", "/CN=ca"]
    made = subprocess.run(
        [*command, "-keyout", str(key), "-out", str(ca)],
        capture_output=True,
        check=False,
    )
    assert made.returncode == 0, made.stderr
    with (
        silent_server() as port,
        running_exporter(
            tmp_path,
            dds_domain,
            f"--icinga2.url=https://127.0.0.1:{port}",
            "--icinga2.username=overseer",
            f"--icinga2.password-file={password}",
            f"--icinga2.ca-file={ca}",
            "--icinga2.interval=5s",
        ) as exporter,
        running_simulator(tmp_path, dds_domain, "--robots=1"),
    ):
        wait_for(lambda: exporter.robot("robot1"), 30, message="robot1")
        wait_for(lambda: "Icinga 2" in exporter.log(), 30, message="the push under way")
        exporter.process.send_signal(signal.SIGTERM)
        time.sleep(1.0)
        assert exporter.process.poll() is None, "the push to a silent Icinga 2 makes the stop slow"
        again = time.monotonic()
        exporter.process.send_signal(signal.SIGTERM)
        status = exporter.process.wait(timeout=10)
        took = time.monotonic() - again
    assert status == 128 + signal.SIGTERM
    assert took < 2, f"the second signal took {took:.1f}s to end it"
    assert "SIGTERM again while stopping: leaving at once" in exporter.log()
