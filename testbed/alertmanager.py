"""Debian's Alertmanager on loopback for tests, configured from the shipped example."""

from __future__ import annotations

import json
import time
import urllib.request
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from testbed.paths import REPO
from testbed.prometheus import RunningServer, running_server

EXAMPLE = REPO / "alert_rules" / "alertmanager.example.yml"


@dataclass
class Alertmanager(RunningServer):
    """A running Alertmanager."""

    def silences(self) -> list[dict[str, Any]]:
        """Every silence it holds, with `status.state` active, pending or expired."""
        with urllib.request.urlopen(self.url + "/api/v2/silences", timeout=10) as response:
            result: list[dict[str, Any]] = json.load(response)
            return result

    def post_alerts(self, *labels: dict[str, str]) -> None:
        """Fire one alert per label set, as Prometheus sends them (for an hour from now)."""
        ends = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(time.time() + 3600))
        body = json.dumps([{"labels": item, "endsAt": ends} for item in labels]).encode()
        headers = {"Content-Type": "application/json"}
        url = self.url + "/api/v2/alerts"
        request = urllib.request.Request(url, data=body, method="POST", headers=headers)
        with urllib.request.urlopen(request, timeout=10):
            pass

    def expire(self, silence_id: str) -> None:
        """Expire a silence, as an operator does in its web UI."""
        request = urllib.request.Request(self.url + f"/api/v2/silence/{silence_id}", method="DELETE")
        with urllib.request.urlopen(request, timeout=10):
            pass

    def alerts(self) -> list[dict[str, Any]]:
        """Every alert it holds, with `status.state` active or suppressed and `status.inhibitedBy`."""
        with urllib.request.urlopen(self.url + "/api/v2/alerts", timeout=10) as response:
            result: list[dict[str, Any]] = json.load(response)
            return result


def example_config(webhook_url: str, timing: dict[str, str] | None = None) -> dict[str, Any]:
    """The shipped example with every receiver posting to `webhook_url`/<receiver name>.

    `timing` (e.g. group_wait, group_interval) replaces those settings on every route when given. Template
    files stay the shipped ones (their paths made absolute, as the config is written elsewhere).
    """
    config: dict[str, Any] = yaml.safe_load(EXAMPLE.read_text(encoding="utf-8"))
    config["templates"] = [str(EXAMPLE.parent / path) for path in config.get("templates", [])]
    for receiver in config["receivers"]:
        for webhook in receiver["webhook_configs"]:
            webhook["url"] = f"{webhook_url}/{receiver['name']}"
    routes = [config["route"]]
    while timing and routes:
        route = routes.pop()
        route.update(timing)
        routes.extend(route.get("routes", []))
    return config


@contextmanager
def running_alertmanager(
    tmp_path: Path, config: dict[str, Any], *flags: str, port: int | None = None
) -> Iterator[Alertmanager]:
    """Run Debian's `prometheus-alertmanager` on loopback, clustering off, until the block ends.

    On `port` when given (a restart on the same port and `tmp_path` keeps its silences), else a free one.
    """
    with running_server(
        tmp_path,
        Alertmanager,
        "prometheus-alertmanager",
        config,
        "--storage.path",
        "--cluster.listen-address=",
        *flags,
        port=port,
    ) as alertmanager:
        yield alertmanager
