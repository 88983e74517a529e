"""Maintenance windows become silences in a real Alertmanager (Debian's), and stop being them.

Each test runs Debian's `prometheus-alertmanager` on loopback (clustering off) and an exporter in the
test process whose `alertmanager.url` points at it; alerts are posted to Alertmanager as Prometheus
posts them, so what is checked is what Alertmanager itself says is silenced.
"""

from __future__ import annotations

import datetime
import json
import time
from base64 import b64encode
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import bcrypt
import pytest

from overseer.app import Exporter
from testbed.alertmanager import Alertmanager, running_alertmanager
from testbed.in_process import call, in_process_exporter
from testbed.ports import free_port
from testbed.processes import wait_for

pytestmark = pytest.mark.servers

HASH = bcrypt.hashpw(b"secret", bcrypt.gensalt(rounds=4)).decode()
WRITER = {"Authorization": "Basic " + b64encode(b"alice:secret").decode()}
ALERTMANAGER_CONFIG = {"route": {"receiver": "nobody"}, "receivers": [{"name": "nobody"}]}


@contextmanager
def exporter(tmp_path: Path, alertmanager_url: str, **sections: Any) -> Iterator[Exporter]:
    """An exporter opening silences in the Alertmanager at `alertmanager_url`; alice may write windows."""
    web_config = tmp_path / "web.yml"
    web_config.write_text(f"basic_auth_users:\n  alice: '{HASH}'\n", encoding="utf-8")
    with in_process_exporter(
        tmp_path,
        web={"config_file": str(web_config), "enable_maintenance_api": True},
        maintenance={"writers": ["alice"], **sections.pop("maintenance", {})},
        alertmanager={"url": alertmanager_url, "resync_interval": "1s", **sections.pop("alertmanager", {})},
        **sections,
    ) as running:
        yield running


def open_window(running: Exporter, robots: str, comment: str = "battery swap") -> dict[str, Any]:
    body = json.dumps({"robots": robots, "duration": "2h", "comment": comment}).encode()
    headers = {**WRITER, "Content-Type": "application/json"}
    status, answer = call(running, "/api/v1/maintenance", "POST", body, headers)
    assert status == 201, answer
    window: dict[str, Any] = answer["window"]
    return window


def end_window(running: Exporter, key: str) -> None:
    status, answer = call(running, f"/api/v1/maintenance/{key}", "DELETE", None, WRITER)
    assert status == 200, answer


def live_silences(alertmanager: Alertmanager) -> list[dict[str, Any]]:
    return [s for s in alertmanager.silences() if s["status"]["state"] != "expired"]


def silenced(alertmanager: Alertmanager) -> dict[str, bool]:
    """Each alert's robot → whether Alertmanager says a silence holds it."""
    return {alert["labels"]["robot"]: bool(alert["status"]["silencedBy"]) for alert in alertmanager.alerts()}


def effects_metric(running: Exporter, name: str) -> dict[str, float]:
    _, body = call(running, "/metrics", headers=WRITER)
    found = {}
    for line in body.decode().splitlines():
        if line.startswith(name + "{") and 'target="alertmanager"' in line:
            labels, _, value = line.rpartition(" ")
            found[labels[len(name) :]] = float(value)
    return found


def test_a_window_silences_its_robots_until_it_is_ended_early(tmp_path: Path) -> None:
    with (
        running_alertmanager(tmp_path, ALERTMANAGER_CONFIG) as alertmanager,
        exporter(tmp_path, alertmanager.url) as running,
    ):
        alertmanager.post_alerts(
            *(
                {"alertname": "RosRobotDown", "robot": robot}
                for robot in ("site_a/r7", "site_a/r8", "site_b/r1")
            )
        )
        wait_for(lambda: len(alertmanager.alerts()) == 3, timeout=10, message="three alerts")
        window = open_window(running, "site_a/", comment="battery swap <b>&\"'")
        silence = wait_for(lambda: live_silences(alertmanager), timeout=10, message="the silence")[0]
        assert silence["matchers"] == [
            {"name": "robot", "value": "site_a/.*", "isRegex": True, "isEqual": True}
        ]
        assert silence["createdBy"] == "alice"
        assert silence["comment"] == f"battery swap <b>&\"' [Overseer maintenance window {window['id']}]"
        assert abs(_unix(silence["endsAt"]) - window["end"]) < 1
        wait_for(
            lambda: silenced(alertmanager) == {"site_a/r7": True, "site_a/r8": True, "site_b/r1": False},
            timeout=10,
            message="site_a's alerts silenced, site_b's not",
        )
        exact = open_window(running, "site_b/r1")
        wait_for(lambda: len(live_silences(alertmanager)) == 2, timeout=10, message="the second silence")
        matchers = [s["matchers"] for s in live_silences(alertmanager)]
        assert [{"name": "robot", "value": "site_b/r1", "isRegex": False, "isEqual": True}] in matchers
        end_window(running, window["id"])
        wait_for(
            lambda: silenced(alertmanager) == {"site_a/r7": False, "site_a/r8": False, "site_b/r1": True},
            timeout=10,
            message="site_a's alerts back once its window ended early",
        )
        [left] = live_silences(alertmanager)
        assert exact["id"] in left["comment"]
        counts = effects_metric(running, "overseer_maintenance_effects_total")
    assert counts == {
        '{action="created",target="alertmanager"}': 2.0,
        '{action="removed",target="alertmanager"}': 1.0,
    }


def test_an_alertmanager_that_is_down_gets_the_silence_once_back(tmp_path: Path) -> None:
    port = free_port()
    with exporter(tmp_path, f"http://127.0.0.1:{port}") as running:
        window = open_window(running, "robot1")
        wait_for(
            lambda: (
                effects_metric(running, "overseer_maintenance_effect_failures_total").get(
                    '{reason="connection",target="alertmanager"}', 0
                )
                >= 1
            ),
            timeout=10,
            message="a failed attempt counted",
        )
        wait_for(
            lambda: (
                effects_metric(running, "overseer_maintenance_effects_pending")
                == {'{target="alertmanager"}': 1}
            ),
            timeout=10,
            message="the silence counted as pending",
        )
        with running_alertmanager(tmp_path, ALERTMANAGER_CONFIG, port=port) as alertmanager:
            silence = wait_for(lambda: live_silences(alertmanager), timeout=40, message="the late silence")[0]
            wait_for(
                lambda: (
                    effects_metric(running, "overseer_maintenance_effects_pending")
                    == {'{target="alertmanager"}': 0.0}
                ),
                timeout=10,
                message="nothing pending",
            )
    assert window["id"] in silence["comment"]


def test_silences_outlive_restarts_a_lost_one_is_made_again_an_expired_one_is_not(tmp_path: Path) -> None:
    port = free_port()
    with running_alertmanager(tmp_path / "first", ALERTMANAGER_CONFIG, port=port) as alertmanager:
        with exporter(tmp_path, alertmanager.url) as running:
            kept = open_window(running, "robot1")
            wait_for(lambda: live_silences(alertmanager), timeout=10, message="the silence")
        with exporter(tmp_path, alertmanager.url) as running:  # the same database: it knows the silence
            wait_for(
                lambda: (
                    effects_metric(running, "overseer_maintenance_last_sync_timestamp_seconds").get(
                        '{target="alertmanager"}', 0
                    )
                    > 0
                ),
                timeout=10,
                message="a sync",
            )
            assert len(alertmanager.silences()) == 1, "a restarted exporter made the silence twice"
    with (
        running_alertmanager(tmp_path / "second", ALERTMANAGER_CONFIG, port=port) as forgetful,
        exporter(tmp_path, forgetful.url) as running,
    ):
        remade = wait_for(lambda: live_silences(forgetful), timeout=15, message="the lost silence remade")
        assert kept["id"] in remade[0]["comment"]
        forgetful.expire(remade[0]["id"])  # an operator's choice, in Alertmanager's own UI
        expired_at = time.time()
        wait_for(
            lambda: (
                effects_metric(running, "overseer_maintenance_last_sync_timestamp_seconds").get(
                    '{target="alertmanager"}', 0
                )
                > expired_at + 2.5
            ),
            timeout=10,
            message="two more syncs",
        )
        assert live_silences(forgetful) == [], "the exporter undid an operator's expiry"


def test_recurring_windows_of_the_configuration_are_silenced_too(tmp_path: Path) -> None:
    every_day = {"robots": "night_shift/", "from": "00:00", "to": "23:59", "time_zone": "UTC"}
    with (
        running_alertmanager(tmp_path, ALERTMANAGER_CONFIG) as alertmanager,
        exporter(
            tmp_path,
            alertmanager.url,
            maintenance={"windows": [{**every_day, "comment": "parked for the night"}]},
        ) as running,
    ):
        silences = wait_for(lambda: live_silences(alertmanager), timeout=10, message="a silence")
        assert running.silences is not None
    assert {s["createdBy"] for s in silences} == {"configuration"}
    assert all(
        s["comment"].startswith("parked for the night [Overseer maintenance window r0@") for s in silences
    )


def _unix(text: str) -> float:
    return datetime.datetime.fromisoformat(text.replace("Z", "+00:00")).timestamp()
