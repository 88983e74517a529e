"""A step of the exporter's wall clock, forward or back, changes no level and records no event.

The exporter runs under libfaketime (Debian's faketime) with its wall clock read from a file the test
rewrites, as an NTP step or a VM resume moves it; the monotonic clock is left alone. Its robots publish
every 5 s from a simulator that keeps the real time, and a maintenance window is open that ends 90 s after
it was opened: a clock judging by wall time would take robots for silent, and end the window at once.
"""

from __future__ import annotations

import json
import time
import urllib.request
from base64 import b64encode
from pathlib import Path
from typing import Any

import bcrypt
import pytest

from testbed.processes import Exporter, running_exporter, running_simulator, wait_for

pytestmark = pytest.mark.servers

LIBFAKETIME = "/usr/lib/x86_64-linux-gnu/faketime/libfaketimeMT.so.1"  # Debian's faketime
WRITER = {"Authorization": "Basic " + b64encode(b"alice:secret").decode(), "Content-Type": "application/json"}


def open_window(exporter: Exporter) -> dict[str, Any]:
    body = json.dumps({"robots": "robot1", "duration": "90s", "comment": "battery swap"}).encode()
    request = urllib.request.Request(exporter.url + "/api/v1/maintenance", body, WRITER, method="POST")
    with urllib.request.urlopen(request, timeout=5) as answer:
        window: dict[str, Any] = json.load(answer)["window"]
        return window


def state(exporter: Exporter) -> dict[str, Any]:
    """Each robot's up, level and components' levels, and whether robot1 is in maintenance."""
    robots = {}
    for name in ("robot1", "robot2"):
        document = exporter.robot(name) or {}
        levels = {c["name"]: c["level"] for c in document.get("components", [])}
        robots[name] = (document.get("up"), document.get("level"), levels)
    maintenance = (exporter.robot("robot1") or {}).get("maintenance")
    return {"robots": robots, "in_maintenance": maintenance is not None}


def test_a_step_of_the_wall_clock_either_way_changes_no_level_and_records_no_event(
    tmp_path: Path, dds_domain: int
) -> None:
    offset = tmp_path / "faketime"
    offset.write_text("+0\n", encoding="utf-8")
    web = tmp_path / "web.yml"
    web.write_text(f"basic_auth_users:\n  alice: '{bcrypt.hashpw(b'secret', bcrypt.gensalt(4)).decode()}'\n")
    config = tmp_path / "overseer.yml"
    config.write_text("maintenance:\n  writers: [alice]\n", encoding="utf-8")
    faked = {
        "LD_PRELOAD": LIBFAKETIME,
        "FAKETIME_TIMESTAMP_FILE": str(offset),
        "FAKETIME_NO_CACHE": "1",
        "FAKETIME_DONT_FAKE_MONOTONIC": "1",
    }
    with (
        running_exporter(
            tmp_path,
            dds_domain,
            "--ingest.workers=1",
            f"--config.file={config}",
            f"--web.config.file={web}",
            "--web.enable-maintenance-api",
            env=faked,
        ) as exporter,
        running_simulator(tmp_path, dds_domain, "--robots=2", "--rate=0.2"),
    ):
        exporter.get = _authorized(exporter)  # type: ignore[method-assign]
        wait_for(lambda: all(state(exporter)["robots"][r][0] for r in ("robot1", "robot2")), 30, message="up")
        time.sleep(11)  # two periods: each robot's 5 s period is known
        open_window(exporter)
        before = state(exporter)
        assert before["in_maintenance"] and before["robots"]["robot1"][0] is True
        events_before = wait_for(
            lambda: (
                [e for e in exporter.get_json("/api/v1/events?limit=1000")["events"]]
                if any(
                    e["kind"] == "maintenance_start" for e in exporter.get_json("/api/v1/events")["events"]
                )
                else None
            ),
            10,
            message="the window's start recorded",
        )
        seen = []
        for step in ("+120", "-3600"):
            offset.write_text(step + "\n", encoding="utf-8")
            deadline = time.monotonic() + 12
            while time.monotonic() < deadline:
                seen.append((step, state(exporter)))
                time.sleep(0.5)
        events_after = exporter.get_json("/api/v1/events?limit=1000")["events"]
        metrics = exporter.get("/metrics").decode()
    changed = [(step, now) for step, now in seen if now != before]
    assert not changed, f"{len(changed)} of {len(seen)} samples changed, first: {changed[:1]} from {before}"
    new = [event for event in events_after if event["id"] not in {e["id"] for e in events_before}]
    assert new == [], new
    assert 'ros_diagnostics_robot_up{robot="robot1"} 1.0' in metrics
    # The reported dates follow the faked wall clock: dated when each message arrived.
    stamp = float(
        metrics.split('ros_diagnostics_robot_last_message_timestamp_seconds{robot="robot1"} ')[1].split()[0]
    )
    assert abs(stamp - (time.time() - 3600)) < 30


def _authorized(exporter: Exporter) -> Any:
    """`exporter.get` with alice's credentials (the web config asks every request for them)."""

    def get(path: str, timeout: float = 5.0) -> bytes:
        request = urllib.request.Request(exporter.url + path, headers=WRITER)
        with urllib.request.urlopen(request, timeout=timeout) as answer:
            body: bytes = answer.read()
            return body

    return get
