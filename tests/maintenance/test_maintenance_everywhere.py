"""One maintenance window, every effect, on real servers: what each tool says during and after it.

Everything runs as deployed, on loopback: the exporter (`overseer run`, with basic auth, the Alertmanager
and the Icinga 2 push configured), the simulator's robots over DDS, Debian's Prometheus on the shipped
fast rules (1s intervals), Debian's Alertmanager on the shipped example (1s batching) posting to a
webhook, and Debian's Icinga 2 with the shipped push ApiUser. robot2 and robot3 are both in ERROR; the
operator puts robot2 in maintenance with `overseer maintenance start`, then ends it early with `end`.
robot3 is the control: it alerts all along.
"""

from __future__ import annotations

import base64
import json
import subprocess
import time
import urllib.request
from pathlib import Path
from typing import Any

import bcrypt
import pytest

from testbed.alertmanager import example_config, running_alertmanager
from testbed.icinga2 import Icinga2, push_api_user, push_config, running_icinga2
from testbed.nagios import run_check
from testbed.processes import Exporter, overseer_command, running_exporter, running_simulator, wait_for
from testbed.prometheus import Prometheus, running_prometheus, shipped_config
from testbed.webhook import running_webhook

pytestmark = pytest.mark.servers

ALICE = "alice:secret"
COMMENT = 'motor swap <drive 2> & "calibration"'


def exporter_config(tmp_path: Path, alertmanager_url: str, icinga: Icinga2) -> Path:
    """The exporter's --config.file: its web config, who may write windows, Alertmanager and Icinga 2."""
    hashed = bcrypt.hashpw(b"secret", bcrypt.gensalt(rounds=4)).decode()
    web = tmp_path / "web.yml"
    web.write_text(f"basic_auth_users:\n  alice: '{hashed}'\n  prometheus: '{hashed}'\n", encoding="utf-8")
    icinga2 = json.loads(push_config(tmp_path, icinga, "everywhere", "1s", timeout="3s").read_text())[
        "icinga2"
    ]
    config = {
        "web": {"config_file": str(web), "enable_maintenance_api": True},
        "maintenance": {"writers": ["alice"]},
        "alertmanager": {"url": alertmanager_url, "resync_interval": "5s"},
        "icinga2": icinga2,
        "events": {"path": str(tmp_path / "events.db")},
    }
    path = tmp_path / "overseer.yml"
    path.write_text(json.dumps(config), encoding="utf-8")
    return path


def api(exporter: Exporter, path: str) -> Any:
    """GET `path` of the exporter as alice."""
    request = urllib.request.Request(exporter.url + path)
    request.add_header("Authorization", "Basic " + base64.b64encode(ALICE.encode()).decode())
    with urllib.request.urlopen(request, timeout=10) as response:
        return json.load(response)


def maintenance(exporter: Exporter, *args: str) -> str:
    """`overseer maintenance ARGS` against the exporter as alice; its output."""
    done = subprocess.run(
        [*overseer_command(), "maintenance", *args, "--url", exporter.url, "-a", ALICE],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    return done.stdout


def firing(prometheus: Prometheus, robot: str) -> set[str]:
    """The alerts Prometheus holds firing for `robot`."""
    return {
        alert["labels"]["alertname"]
        for alert in prometheus.alerts()
        if alert["labels"].get("robot") == robot and alert["state"] == "firing"
    }


def host_downtime_depth(icinga: Icinga2, host: str) -> int:
    answer = icinga.api("GET", "/v1/objects/hosts", {"host": host, "attrs": ["downtime_depth"]})
    return int(answer["results"][0]["attrs"]["downtime_depth"])


def test_one_window_quiets_prometheus_alertmanager_and_icinga_and_every_view_says_why(
    tmp_path: Path, dds_domain: int
) -> None:
    with (
        running_webhook() as webhook,
        running_alertmanager(
            tmp_path, example_config(webhook.url, {"group_wait": "1s", "group_interval": "1s"})
        ) as alertmanager,
        running_icinga2(tmp_path / "icinga2", push_api_user()) as icinga,
        running_exporter(
            tmp_path,
            dds_domain,
            f"--config.file={exporter_config(tmp_path, alertmanager.url, icinga)}",
            "--fleet.stale-after=2s",
            "--fleet.robot-timeout=3s",
        ) as exporter,
    ):
        prometheus_config = shipped_config("prometheus-fast.yml", [exporter.url], alertmanager.url, "1s")
        prometheus_config["scrape_configs"][0]["basic_auth"] = {
            "username": "prometheus",
            "password": "secret",
        }
        opened = maintenance(exporter, "start", "robot2", "-d", "2h", "-c", COMMENT)
        window = opened.split(":", 1)[0]
        fleet = ["--robots=3", "--components=5", "--warn=0", "--error=0"]
        events = [f"--event=0:{robot}:/Motor/Motor1:ERROR" for robot in ("robot2", "robot3")]
        with (
            running_prometheus(tmp_path, prometheus_config) as prometheus,
            running_simulator(tmp_path, dds_domain, *fleet, *events),
        ):
            # During the window: robot3 alerts (the control), robot2 does not, anywhere.
            wait_for(lambda: "RosRobotError" in firing(prometheus, "robot3"), 60, message="robot3's alert")
            wait_for(
                lambda: webhook.first("firing", alertname="RosRobotError", robot="robot3"),
                30,
                message="robot3's page",
            )
            assert firing(prometheus, "robot2") == set()
            assert prometheus.query('ros_diagnostics_robot_maintenance{robot="robot2"}')[0]["value"][1] == "1"
            assert webhook.alerts(robot="robot2") == []
            [silence] = [s for s in alertmanager.silences() if s["status"]["state"] == "active"]
            assert silence["matchers"][0]["value"] == "robot2" and silence["createdBy"] == "alice"
            wait_for(lambda: host_downtime_depth(icinga, "robot2") > 0, 30, message="robot2's downtime")
            assert host_downtime_depth(icinga, "robot3") == 0
            checked = run_check("--url", exporter.url, "-r", "robot2", "-a", ALICE)
            assert checked.state == 2 and f"alice: {COMMENT}]" in checked.output
            robot = api(exporter, "/api/v1/robots/robot2")
            assert robot["maintenance"]["window"] == window and robot["state"] == "ERROR"
            started = api(exporter, "/api/v1/events?robot=robot2")["events"]
            assert [(e["kind"], e["message"]) for e in started if e["kind"].startswith("maintenance")] == [
                ("maintenance_start", COMMENT)
            ]

            # The window ends early: every tool turns back to robot2's real state.
            ended_at = time.time()
            maintenance(exporter, "end", window)
            page = wait_for(
                lambda: webhook.first("firing", alertname="RosRobotError", robot="robot2"),
                60,
                message="robot2's alert once its window ended",
            )
            assert page.received_at - ended_at > 15, (
                "the alert waited for its `for:` from the end of the window"
            )
            assert all(s["status"]["state"] == "expired" for s in alertmanager.silences())
            wait_for(
                lambda: host_downtime_depth(icinga, "robot2") == 0, 30, message="robot2's downtime removed"
            )
            checked = run_check("--url", exporter.url, "-r", "robot2", "-a", ALICE)
            assert checked.state == 2 and "maintenance" not in checked.output
            kinds = [e["kind"] for e in api(exporter, "/api/v1/events?robot=robot2")["events"]]
            assert "maintenance_end" in kinds
