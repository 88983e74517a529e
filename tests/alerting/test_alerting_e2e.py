"""Alerting end to end: shipped rules and Alertmanager example on real servers, timed from fault to webhook.

Debian's Prometheus runs the shipped rules, Debian's Alertmanager the shipped example, next to a webhook
receiver, the exporter and the simulator, all on loopback.

robot1's /Laser/Laser1 turns ERROR and back to OK while robot2 stops. The webhook must get the firing and the
resolved RosRobotError and RosRobotDown; robot2's RosRobotStale must be inhibited. The test times
each notification from the exporter receiving its cause, and prints the times.

By default it runs the fast profile's rules with 1s intervals and 1s Alertmanager batching, to keep the suite
quick. OVERSEER_E2E_PROFILE=fast or =default runs a shipped profile exactly as deployed (Prometheus intervals,
rules, the Alertmanager example's timing, the exporter's default timeouts): that measures the numbers in
bench/README.md and takes about 2 and 8 minutes.

The last test gives the shipped Alertmanager example alerts labelled as the rules label them, with the
inventory labels site, model and team: each reaches the receiver of its site or team, and a robot never heard
inhibits its own other alerts and no other site's.
"""

from __future__ import annotations

import json
import os
import subprocess
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

from overseer.simulator.design import aggregated_statuses, initial_levels, leaf_components
from testbed.alertmanager import Alertmanager, example_config, running_alertmanager
from testbed.paths import REPO
from testbed.processes import Exporter, running_exporter, running_simulator, wait_for
from testbed.prometheus import (
    Prometheus,
    load_rules,
    parse_duration,
    running_prometheus,
    shipped_config,
)
from testbed.webhook import ReceivedAlert, WebhookReceiver, running_webhook

pytestmark = pytest.mark.servers  # every test here starts real servers or middleware


ROBOT, COMPONENT, DOWN_ROBOT = "robot1", "/Laser/Laser1", "robot2"
# Seconds after the simulator starts: the exporter follows both robots by then, and Prometheus scraped them.
FLIP_AT = 5
# Room for process start-up and a loaded machine, on top of what the configuration makes each alert wait.
SLACK = 10.0


@dataclass(frozen=True)
class Profile:
    """How the pipeline runs: a shipped Prometheus config, and what the test changes to go faster."""

    prometheus_config: str
    interval: str | None = None
    alertmanager_timing: dict[str, str] = field(default_factory=dict)
    stale_after: int = 5
    robot_timeout: int = 10


PROFILES = {
    "suite": Profile("prometheus-fast.yml", "1s", {"group_wait": "1s", "group_interval": "1s"}, 2, 3),
    "fast": Profile("prometheus-fast.yml"),
    "default": Profile("prometheus.yml"),
}
PROFILE_NAME = os.environ.get("OVERSEER_E2E_PROFILE", "suite")


@dataclass(frozen=True)
class Budget:
    """The most each notification may take from its cause in this profile (seconds), and the rules' `for:`."""

    error: float
    resolved: float
    down: float
    stale: float
    warning_group_wait: float
    error_for: float
    down_for: float
    never_heard: float


def route_setting(config: dict[str, Any], severity: str, key: str) -> float:
    """A timing of the Alertmanager route for `severity`, inherited from the root route when unset."""
    (route,) = [route for route in config["route"]["routes"] if f'severity="{severity}"' in route["matchers"]]
    return parse_duration(route.get(key, config["route"][key]))


def budget(prometheus: dict[str, Any], alertmanager: dict[str, Any], profile: Profile) -> Budget:
    """What the configurations make each alert wait: `for:`, two scrapes, two evaluations and group_wait."""
    rules = {
        rule["alert"]: rule
        for path in prometheus["rule_files"]
        for rule in load_rules(Path(path))
        if "alert" in rule
    }
    settings = prometheus["global"]
    pipeline = 2 * parse_duration(settings["scrape_interval"]) + 2 * parse_duration(
        settings["evaluation_interval"]
    )
    pipeline += SLACK
    critical_wait = route_setting(alertmanager, "critical", "group_wait")

    def for_(alert: str) -> float:
        return parse_duration(rules[alert]["for"])

    return Budget(
        error=for_("RosRobotError") + pipeline + critical_wait,
        resolved=pipeline + route_setting(alertmanager, "critical", "group_interval"),
        down=profile.robot_timeout + for_("RosRobotDown") + pipeline + critical_wait,
        stale=profile.robot_timeout + for_("RosRobotStale") + pipeline,
        warning_group_wait=route_setting(alertmanager, "warning", "group_wait"),
        error_for=for_("RosRobotError"),
        down_for=for_("RosRobotDown"),
        never_heard=for_("RosRobotNeverHeard")
        + pipeline
        + route_setting(alertmanager, "warning", "group_wait"),
    )


def received_at_level(exporter: Exporter, level: int, timeout: float) -> float:
    """When the exporter received the status that put robot1's /Laser/Laser1 at `level` (unix time)."""

    def component() -> dict[str, Any] | None:
        robot = exporter.robot(ROBOT) or {"components": []}
        found = [c for c in robot["components"] if c["name"] == COMPONENT and c["level"] == level]
        return found[0] if found else None

    found = wait_for(component, timeout, interval=0.05, message=f"{ROBOT} {COMPONENT} at level {level}")
    return float(found["last_update"])


@dataclass
class Pipeline:
    """A profile's alert path on test servers, and what its configuration makes each alert wait."""

    alertmanager: Alertmanager
    exporter: Exporter
    limits: Budget


@contextmanager
def alert_pipeline(
    tmp_path: Path,
    dds_domain: int,
    profile: Profile,
    webhook: WebhookReceiver,
    alertmanager_config: dict[str, Any],
    *exporter_flags: str,
) -> Iterator[Pipeline]:
    """Alertmanager, the exporter and Prometheus with the profile's shipped config, until the block ends."""
    exporter_args = [
        f"--fleet.stale-after={profile.stale_after}s",
        f"--fleet.robot-timeout={profile.robot_timeout}s",
        *exporter_flags,
    ]
    with (
        running_alertmanager(tmp_path, alertmanager_config) as alertmanager,
        running_exporter(tmp_path, dds_domain, *exporter_args) as exporter,
    ):
        prometheus_config = shipped_config(
            profile.prometheus_config, [exporter.url], alertmanager.url, profile.interval
        )
        limits = budget(prometheus_config, alertmanager_config, profile)
        with (
            running_prometheus(tmp_path, prometheus_config) as prometheus,
            explained_failures(webhook, prometheus, exporter),
        ):
            yield Pipeline(alertmanager, exporter, limits)


def notification(webhook: WebhookReceiver, status: str, timeout: float, **labels: str) -> ReceivedAlert:
    """The first `status` notification with `labels`, waiting for it up to `timeout`."""
    alert: ReceivedAlert = wait_for(
        lambda: webhook.first(status, **labels), timeout, message=f"a {status} notification with {labels}"
    )
    return alert


def test_error_notifies_then_resolves_and_a_down_robot_inhibits_its_other_alerts(
    tmp_path: Path, dds_domain: int, capsys: pytest.CaptureFixture[str]
) -> None:
    profile = PROFILES[PROFILE_NAME]
    with running_webhook() as webhook:
        alertmanager_config = example_config(webhook.url, profile.alertmanager_timing)
        with alert_pipeline(tmp_path, dds_domain, profile, webhook, alertmanager_config) as pipeline:
            exporter, limits = pipeline.exporter, pipeline.limits
            events = [
                f"--event={FLIP_AT}:{ROBOT}:{COMPONENT}:ERROR",
                f"--event={FLIP_AT + round(limits.error)}:{ROBOT}:{COMPONENT}:OK",
                f"--event={FLIP_AT}:{DOWN_ROBOT}:stop",
            ]
            fleet = ["--robots=2", "--components=5", "--warn=0", "--error=0", *events]
            with running_simulator(tmp_path, dds_domain, *fleet):
                flipped_at = received_at_level(exporter, 2, timeout=FLIP_AT + SLACK)
                fired = notification(webhook, "firing", limits.error, alertname="RosRobotError", robot=ROBOT)
                assert fired.labels["severity"] == "critical" and fired.path == "/fleet-critical"
                assert fired.annotations["message"] == f"/Laser: Error; {COMPONENT}: No scans received"

                stopped_at = robot_went_down(exporter)
                robot_down = notification(
                    webhook, "firing", limits.down, alertname="RosRobotDown", robot=DOWN_ROBOT
                )
                assert robot_down.labels["severity"] == "critical" and robot_down.path == "/fleet-critical"

                recovered_at = received_at_level(exporter, 0, timeout=limits.error + SLACK)
                resolved = notification(
                    webhook, "resolved", limits.resolved, alertname="RosRobotError", robot=ROBOT
                )

                inhibited = wait_for(
                    lambda: stale_alerts(pipeline.alertmanager.alerts(), DOWN_ROBOT),
                    limits.stale,
                    message=f"{DOWN_ROBOT}'s RosRobotStale in Alertmanager",
                )
                assert all(alert["status"]["state"] == "suppressed" for alert in inhibited), inhibited
                assert all(alert["status"]["inhibitedBy"] for alert in inhibited), inhibited
                # Give the warning route's batch time to go out, had the inhibition not held.
                time.sleep(limits.warning_group_wait + 2)
                assert {alert.labels["alertname"] for alert in webhook.alerts(robot=DOWN_ROBOT)} == {
                    "RosRobotDown"
                }

    error_latency = fired.received_at - flipped_at
    resolved_latency = resolved.received_at - recovered_at
    down_latency = robot_down.received_at - stopped_at
    with capsys.disabled():
        print(
            f"\n[alerting e2e, {PROFILE_NAME} profile] component ERROR -> firing notification"
            f" {error_latency:.1f}s, back to OK -> resolved {resolved_latency:.1f}s,"
            f" robot stops -> RosRobotDown {down_latency:.1f}s"
        )
    assert limits.error_for <= error_latency <= limits.error
    assert resolved_latency <= limits.resolved
    # A robot that leaves the domain is down when its writer goes, before robot_timeout runs out: `for:` is
    # the only wait that must always pass.
    assert limits.down_for <= down_latency <= limits.down


@contextmanager
def explained_failures(
    webhook: WebhookReceiver, prometheus: Prometheus, exporter: Exporter
) -> Iterator[None]:
    """Add what each stage of the pipeline holds to an assertion that fails in the block."""
    try:
        yield
    except AssertionError as failure:
        received = [(alert.status, alert.labels) for alert in webhook.alerts()]
        rules = [(alert["state"], alert["labels"]) for alert in prometheus.alerts()]
        fleet = exporter.get("/api/v1/robots").decode()
        raise AssertionError(
            f"{failure}\nwebhook received: {received}\nPrometheus alerts: {rules}\nexporter: {fleet}"
        ) from failure


def robot_went_down(exporter: Exporter) -> float:
    """Wait for robot2 to count as down; return when the exporter received its last message (unix time)."""

    def down() -> dict[str, Any] | None:
        robot = exporter.robot(DOWN_ROBOT)
        return robot if robot is not None and not robot["up"] else None

    robot: dict[str, Any] = wait_for(down, FLIP_AT + 2 * SLACK, message=f"{DOWN_ROBOT} down")
    return float(robot["last_message"])


def stale_alerts(alerts: list[dict[str, Any]], robot: str) -> list[dict[str, Any]]:
    """Alertmanager's RosRobotStale alerts for `robot`."""
    return [
        alert
        for alert in alerts
        if alert["labels"]["alertname"] == "RosRobotStale" and alert["labels"].get("robot") == robot
    ]


BATTERY_ROBOT, BATTERY = "alpha1", "/Power/Robot Battery"  # the simulator's battery says "Battery critical"
EXTERNAL_URL = "https://ops.example/overseer"
TEMPLATE = REPO / "alert_rules" / "overseer.tmpl"
# What the example's comment tells operators to put in a chat receiver; here Slack's "API" is the webhook.
CHAT_TITLE, CHAT_TEXT = '{{ template "overseer.title" . }}', '{{ template "overseer.text" . }}'


def test_battery_error_notifies_with_its_message_and_a_link_to_the_robot_rendered_by_the_shipped_template(
    tmp_path: Path, dds_domain: int
) -> None:
    profile = PROFILES["suite"]
    with running_webhook() as webhook:
        alertmanager_config = example_config(webhook.url, profile.alertmanager_timing)
        (critical,) = [r for r in alertmanager_config["receivers"] if r["name"] == "fleet-critical"]
        chat_config = {"api_url": f"{webhook.url}/chat", "title": CHAT_TITLE, "text": CHAT_TEXT}
        critical["slack_configs"] = [chat_config]
        fleet = [
            "--robots=1",
            "--components=5",
            "--warn=0",
            "--error=0",
            "--namespace-prefix=alpha",
            f"--event={FLIP_AT}:{BATTERY_ROBOT}:{BATTERY}:ERROR",
        ]
        with (
            alert_pipeline(
                tmp_path,
                dds_domain,
                profile,
                webhook,
                alertmanager_config,
                "--web.external-url=" + EXTERNAL_URL,
            ) as pipeline,
            running_simulator(tmp_path, dds_domain, *fleet),
        ):
            limits = pipeline.limits
            fired = notification(
                webhook,
                "firing",
                FLIP_AT + SLACK + limits.error,
                alertname="RosRobotError",
                robot=BATTERY_ROBOT,
            )
            chat = wait_for(
                lambda: chat_text_with(webhook, f"{BATTERY_ROBOT} ERROR — "),
                SLACK,
                message="the chat notification of the battery",
            )
    assert fired.annotations["message"] == f"/Power: Error; {BATTERY}: Battery critical"
    assert fired.annotations["status_page_url"] == f"{EXTERNAL_URL}/?robot={BATTERY_ROBOT}"
    assert fired.labels["external_url"] == EXTERNAL_URL
    # Alertmanager rendered the shipped template into the chat notification: the battery's line and its links.
    lines = chat["text"].splitlines()
    battery_line = f"{BATTERY_ROBOT} ERROR — /Power: Error; {BATTERY}: Battery critical"
    at = lines.index(battery_line)
    assert lines[at + 1 : at + 3] == [
        f"  status page: {EXTERNAL_URL}/?robot={BATTERY_ROBOT}",
        "  runbook: docs/runbook.md#rosroboterror",
    ]
    # The webhook got the same notification as JSON: amtool renders it with the template to the same text.
    assert render_template(tmp_path, CHAT_TEXT, fired.notification) == chat["text"]
    assert render_template(tmp_path, CHAT_TITLE, fired.notification) == chat["title"]


def chat_text_with(webhook: WebhookReceiver, line: str) -> dict[str, Any] | None:
    """The first attachment of a chat notification whose text holds `line`, if any arrived."""
    for body in webhook.bodies("/chat"):
        for attachment in body.get("attachments", []):
            if line in attachment.get("text", ""):
                return dict(attachment)
    return None


def render_template(tmp_path: Path, text: str, data: dict[str, Any]) -> str:
    """`text` rendered by `amtool template render` with the shipped templates and `data`."""
    data_path = tmp_path / "notification.json"
    data_path.write_text(json.dumps(data), encoding="utf-8")
    result = subprocess.run(
        [
            "amtool",
            "template",
            "render",
            f"--template.glob={TEMPLATE}",
            f"--template.text={text}",
            f"--template.data={data_path}",
        ],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    return result.stdout


def test_a_robot_with_many_failing_components_notifies_once_listing_each_with_its_message(
    tmp_path: Path, dds_domain: int
) -> None:
    profile = PROFILES["suite"]
    leaves, error, warn = 20, 8, 2
    fleet = ["--robots=2", f"--components={leaves}", f"--warn={warn}", f"--error={error}"]
    # The simulator's own design is the oracle: every status of the robot at ERROR, with its message.
    components = leaf_components(leaves)
    statuses = aggregated_statuses(components, initial_levels(components, warn, error), set())
    expected = "; ".join(
        f"{status.name}: {status.message}"
        for status in sorted(statuses, key=lambda s: s.name)
        if status.level == 2
    )
    assert expected.count(";") >= error  # eight leaves and their groups
    with running_webhook() as webhook:
        alertmanager_config = example_config(webhook.url, profile.alertmanager_timing)
        with (
            alert_pipeline(tmp_path, dds_domain, profile, webhook, alertmanager_config) as pipeline,
            running_simulator(tmp_path, dds_domain, *fleet),
        ):
            limits = pipeline.limits
            for robot in ("robot1", "robot2"):
                fired = notification(
                    webhook,
                    "firing",
                    FLIP_AT + SLACK + limits.error,
                    alertname="RosRobotError",
                    robot=robot,
                )
                assert fired.annotations["message"] == expected
            # A few more evaluations and notification rounds: still one alert per robot, and no warning.
            time.sleep(5)
            firing = [alert for alert in webhook.alerts() if alert.status == "firing"]
            assert {(alert.labels["alertname"], alert.labels["robot"]) for alert in firing} == {
                ("RosRobotError", "robot1"),
                ("RosRobotError", "robot2"),
            }


def test_alerts_reach_their_site_or_team_and_a_robot_never_heard_inhibits_only_its_own_alerts(
    tmp_path: Path,
) -> None:
    # The shipped example on a real Alertmanager, given alerts labelled as the rules label them: two sites
    # whose exporters have the same address each have a robot1, and only site_a's was never heard.
    address = "overseer:9849"
    never_heard = {"alertname": "RosRobotNeverHeard", "severity": "warning", "robot": "robot1"}
    stale = {"alertname": "RosRobotStale", "severity": "warning", "robot": "robot1"}
    unlisted = {"alertname": "RosRobotError", "severity": "critical", "robot": "robot3", "instance": address}
    site_a = {"instance": address, "site": "site_a", "model": "tb4", "team": "logistics"}
    site_b = {"instance": address, "site": "site_b", "model": "tb4", "team": "inspection"}
    with running_webhook() as webhook:
        config = example_config(webhook.url, {"group_wait": "1s", "group_interval": "1s"})
        with running_alertmanager(tmp_path, config) as alertmanager:
            alertmanager.post_alerts(
                never_heard | site_a,
                stale | site_a,
                stale | site_b,
                {"alertname": "RosRobotDown", "severity": "critical", "robot": "robot2"} | site_b,
                unlisted,
            )
            expected = {
                ("RosRobotNeverHeard", "robot1", "/team-logistics"),
                ("RosRobotStale", "robot1", "/team-inspection"),
                ("RosRobotDown", "robot2", "/site-b-oncall"),
                ("RosRobotError", "robot3", "/fleet-critical"),
            }

            def notified() -> set[tuple[str, str, str]] | None:
                found = {(a.labels["alertname"], a.labels["robot"], a.path) for a in webhook.alerts()}
                return found if found >= expected else None

            wait_for(notified, SLACK, message=f"notifications {expected}")
            held = {
                (alert["labels"]["alertname"], alert["labels"]["site"]): alert["status"]
                for alert in alertmanager.alerts()
                if alert["labels"]["robot"] == "robot1"
            }
            # Another round of the warning routes' batches, had the inhibition not held.
            time.sleep(3)
            received = {(a.labels["alertname"], a.labels["robot"], a.path) for a in webhook.alerts()}
    assert held[("RosRobotStale", "site_a")]["state"] == "suppressed"
    assert held[("RosRobotStale", "site_a")]["inhibitedBy"]
    assert held[("RosRobotStale", "site_b")]["state"] == "active"
    assert received == expected


def test_a_listed_robot_never_heard_notifies_its_team_with_the_inventorys_labels(
    tmp_path: Path, dds_domain: int
) -> None:
    # The whole pipeline: the exporter reads an inventory with a robot that never comes up, Prometheus
    # evaluates the shipped rules (RosRobotNeverHeard, the fast profile's for:) and Alertmanager routes it.
    profile = PROFILES[PROFILE_NAME]
    inventory = tmp_path / "inventory.yml"
    inventory.write_text(
        "robots:\n  ghost: {labels: {site: site_a, model: tb4, team: logistics}}\n", encoding="utf-8"
    )
    with running_webhook() as webhook:
        alertmanager_config = example_config(webhook.url, profile.alertmanager_timing)
        with alert_pipeline(
            tmp_path, dds_domain, profile, webhook, alertmanager_config, f"--inventory.file={inventory}"
        ) as pipeline:
            alert = notification(
                webhook, "firing", pipeline.limits.never_heard, alertname="RosRobotNeverHeard", robot="ghost"
            )
    assert alert.path == "/team-logistics"
    assert {key: alert.labels[key] for key in ("site", "model", "team", "severity")} == {
        "site": "site_a",
        "model": "tb4",
        "team": "logistics",
        "severity": "warning",
    }
