"""The HTTP endpoint: /metrics, /api/v1, /-/healthy and the status page, on a bounded thread pool."""

from __future__ import annotations

import gzip
import json
import logging
import socket
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from typing import Any
from urllib.parse import unquote, urlsplit

from prometheus_client.exposition import choose_encoder
from prometheus_client.registry import CollectorRegistry

from overseer.api import robot_document, robots_document
from overseer.exposition import CONTENT_TYPE as EXPOSITION_CONTENT_TYPE
from overseer.exposition import FleetExposition
from overseer.model import FleetModel

log = logging.getLogger(__name__)

ROBOTS_PATH = "/api/v1/robots"
MAX_CONCURRENT_REQUESTS = 16
REQUEST_TIMEOUT_SECONDS = 10.0


class OverseerServer(ThreadingHTTPServer):
    """A threading HTTP server that serves one fleet model and one registry."""

    daemon_threads = True
    request_queue_size = 64

    def __init__(
        self,
        address: tuple[str, int],
        model: FleetModel,
        registry: CollectorRegistry,
        exposition: FleetExposition,
    ) -> None:
        """Bind to `address` ('' host for every interface; IPv6 when the host has a colon)."""
        if ":" in address[0]:
            self.address_family = socket.AF_INET6
        self.model = model
        self.registry = registry
        self.exposition = exposition
        self.slots = threading.BoundedSemaphore(MAX_CONCURRENT_REQUESTS)
        self.status_page = resources.files("overseer.web").joinpath("index.html").read_bytes()
        super().__init__(address, _Handler)

    @property
    def url(self) -> str:
        """The base URL the server answers on."""
        host, port = self.server_address[:2]
        shown = "127.0.0.1" if host in ("", "0.0.0.0") else str(host)
        return f"http://{'[' + shown + ']' if ':' in shown else shown}:{port}"


class _Handler(BaseHTTPRequestHandler):
    server: OverseerServer
    timeout = REQUEST_TIMEOUT_SECONDS
    protocol_version = "HTTP/1.1"
    server_version = "overseer"

    def do_GET(self) -> None:
        if not self.server.slots.acquire(timeout=REQUEST_TIMEOUT_SECONDS):
            self._send(503, b"too many concurrent requests\n", "text/plain; charset=utf-8")
            return
        try:
            self._route(head_only=False)
        finally:
            self.server.slots.release()

    def do_HEAD(self) -> None:
        self._route(head_only=True)

    def _route(self, head_only: bool) -> None:
        path = urlsplit(self.path).path
        if path == "/metrics":
            self._metrics(head_only)
        elif path == "/-/healthy" or path == "/-/ready":
            self._send(200, b"OK\n", "text/plain; charset=utf-8", head_only)
        elif path == ROBOTS_PATH or path == ROBOTS_PATH + "/":
            self._json(200, robots_document(self.server.model.snapshot()), head_only)
        elif path.startswith(ROBOTS_PATH + "/"):
            self._robot(unquote(path[len(ROBOTS_PATH) + 1 :]), head_only)
        elif path in ("/", "/index.html"):
            self._send(200, self.server.status_page, "text/html; charset=utf-8", head_only)
        else:
            self._json(404, {"error": f"no such path {path!r}"}, head_only)

    def _robot(self, name: str, head_only: bool) -> None:
        snapshot = self.server.model.snapshot()
        robot = snapshot.find(name)
        if robot is None:
            self._json(404, {"error": f"unknown robot {name!r}"}, head_only)
        else:
            self._json(200, robot_document(snapshot, robot), head_only)

    def _metrics(self, head_only: bool) -> None:
        accept = self.headers.get("Accept", "")
        if "application/openmetrics-text" in accept:
            encoder, content_type = choose_encoder(accept)
            body = encoder(self.server.registry)
        else:
            body, content_type = self.server.exposition.render(), EXPOSITION_CONTENT_TYPE
        self._send(200, body, content_type, head_only, compressible=True)

    def _json(self, status: int, document: dict[str, Any], head_only: bool) -> None:
        body = json.dumps(document, ensure_ascii=False, allow_nan=False).encode("utf-8")
        self._send(status, body, "application/json; charset=utf-8", head_only, compressible=True)

    def _send(
        self, status: int, body: bytes, content_type: str, head_only: bool = False, compressible: bool = False
    ) -> None:
        if compressible and "gzip" in self.headers.get("Accept-Encoding", ""):
            body = gzip.compress(body, compresslevel=1)
            encoding: str | None = "gzip"
        else:
            encoding = None
        self.send_response(status)
        self.send_header("Content-Type", content_type)
        self.send_header("Content-Length", str(len(body)))
        if encoding:
            self.send_header("Content-Encoding", encoding)
        self.send_header("Cache-Control", "no-store")
        self.end_headers()
        if not head_only:
            self.wfile.write(body)

    def log_message(self, format: str, *args: Any) -> None:
        log.debug("%s %s", self.address_string(), format % args)
