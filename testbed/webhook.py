"""A small webhook receiver on loopback that records Alertmanager's notifications and when they arrived.

Besides webhook notifications it keeps every JSON body posted to it, such as a Slack notification that
Alertmanager rendered from templates (a `slack_configs` receiver whose api_url points here).
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any


@dataclass(frozen=True)
class ReceivedAlert:
    """One alert of one notification: its webhook path (the receiver), status, labels and arrival time."""

    path: str
    status: str
    labels: dict[str, str]
    received_at: float
    annotations: dict[str, str] = field(default_factory=dict)
    notification: dict[str, Any] = field(default_factory=dict)  # the whole webhook body it came in


class WebhookReceiver:
    """Records every alert Alertmanager posts to it, in arrival order."""

    def __init__(self) -> None:
        """Start listening on a free loopback port (served once `serve_forever` runs)."""
        self._lock = threading.Lock()
        self._alerts: list[ReceivedAlert] = []
        self._bodies: list[tuple[str, dict[str, Any]]] = []
        self.server = ThreadingHTTPServer(("127.0.0.1", 0), self._handler())
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}"

    def _handler(self) -> type[BaseHTTPRequestHandler]:
        receiver = self

        class Handler(BaseHTTPRequestHandler):
            def do_POST(self) -> None:
                """Record one Alertmanager notification."""
                received_at = time.time()
                body = self.rfile.read(int(self.headers["Content-Length"]))
                receiver.record(self.path, json.loads(body), received_at)
                self.send_response(200)
                self.end_headers()

            def log_message(self, format: str, *args: Any) -> None:
                """Keep the test output quiet."""

        return Handler

    def record(self, path: str, payload: dict[str, Any], received_at: float) -> None:
        """Store the alerts of one webhook payload (none for other JSON bodies, which are kept whole)."""
        alerts = [
            ReceivedAlert(
                path, alert["status"], alert["labels"], received_at, alert.get("annotations", {}), payload
            )
            for alert in payload.get("alerts", [])
        ]
        with self._lock:
            self._alerts.extend(alerts)
            self._bodies.append((path, payload))

    def bodies(self, path: str) -> list[dict[str, Any]]:
        """Every JSON body posted to `path`, in arrival order."""
        with self._lock:
            return [body for where, body in self._bodies if where == path]

    def alerts(self, **labels: str) -> list[ReceivedAlert]:
        """The alerts received so far whose labels include `labels`."""
        with self._lock:
            received = list(self._alerts)
        return [alert for alert in received if labels.items() <= alert.labels.items()]

    def first(self, status: str, **labels: str) -> ReceivedAlert | None:
        """The first alert received with `status` (firing or resolved) and `labels`, if any."""
        return next((alert for alert in self.alerts(**labels) if alert.status == status), None)


@contextmanager
def running_webhook() -> Iterator[WebhookReceiver]:
    """Serve a WebhookReceiver on a thread until the block ends."""
    receiver = WebhookReceiver()
    thread = threading.Thread(target=receiver.server.serve_forever, daemon=True)
    thread.start()
    try:
        yield receiver
    finally:
        receiver.server.shutdown()
        receiver.server.server_close()
        thread.join()
