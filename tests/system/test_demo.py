"""`overseer demo`: the exporter and a simulated fleet, serving /metrics within 15 seconds."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from testbed.ports import free_port
from testbed.processes import Exporter, overseer_command, spawn, wait_for, wait_until_healthy

pytestmark = pytest.mark.servers  # every test here starts real servers or middleware


def test_demo_serves_the_simulated_fleet_within_15_seconds(tmp_path: Path, dds_domain: int) -> None:
    port = free_port()
    started = time.monotonic()
    log_path = tmp_path / "demo.log"
    process = spawn(
        [*overseer_command(), "demo", f"--web.listen-address=127.0.0.1:{port}", f"--domain={dds_domain}"],
        log_path,
        cwd=tmp_path,
    )
    demo = Exporter(process, log_path, f"http://127.0.0.1:{port}")
    try:
        wait_until_healthy(demo, 15)
        wait_for(
            lambda: demo.get("/metrics").count(b"ros_diagnostics_robot_up{") == 6, 15, message="6 robots"
        )
        assert time.monotonic() - started < 15
        assert f"status page  http://127.0.0.1:{port}/" in demo.log()
    finally:
        assert demo.stop() == 0
