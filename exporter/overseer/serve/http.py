"""The HTTP endpoint: /metrics, /api/v1, /-/healthy and the status page, bounded against slow or many clients.

A thread per connection, at most `MAX_CONNECTIONS` of them (more are closed at once), of which at most
`MAX_CONCURRENT_REQUESTS` build an answer at a time. Reading a request, and writing an answer, must each
end within `REQUEST_TIMEOUT_SECONDS` in all, not per byte, so a client trickling bytes is cut off. The TLS
handshake, when the web config asks for TLS, runs in the connection's thread under the same deadline, so
a slow TLS client never blocks the accept loop. Basic auth, when configured, guards every path.
"""

from __future__ import annotations

import gzip
import io
import json
import logging
import select
import socket
import ssl
import sys
import threading
import time
from collections.abc import Callable, Mapping
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from typing import TYPE_CHECKING, Any
from urllib.parse import parse_qs, unquote, urlsplit

from overseer.fleet.interface import Fleet, FleetPartUnavailable
from overseer.heap_trim import trim_after_answer
from overseer.routes import MAX_BODY_BYTES, ApiRequest, JsonRoute
from overseer.serve.api_query import ApiQueryError, parse_component_query, parse_robot_query
from overseer.serve.assembler import Body, ExpositionAssembler
from overseer.serve.negotiation import accepts_gzip, negotiate_format
from overseer.serve.render_timing import RenderTiming
from overseer.serve.status_page import FAVICON, PAGE_HEADERS, STATIC_PREFIX, PageFile, load_page_files
from overseer.serve.web_config import REALM, WebSecurity

if TYPE_CHECKING:
    from _typeshed import ReadableBuffer, WriteableBuffer

log = logging.getLogger(__name__)

ROBOTS_PATH = "/api/v1/robots"
COMPONENTS_PATH = "/api/v1/components"
MAX_CONNECTIONS = 128
MAX_CONCURRENT_REQUESTS = 16
REQUEST_TIMEOUT_SECONDS = 10.0
_TLS_HANDSHAKE_RECORD = b"\x16"
_NOT_TLS_ANSWER = (
    b"HTTP/1.0 400 Bad Request\r\nContent-Type: text/plain; charset=utf-8\r\nConnection: close\r\n\r\n"
    b"Client sent an HTTP request to an HTTPS server.\n"
)


class OverseerServer(ThreadingHTTPServer):
    """A threading HTTP server that serves one fleet, and JSON routes of other outputs beside it."""

    daemon_threads = True
    block_on_close = False  # stopping never waits for a slow client
    request_queue_size = 64

    def __init__(
        self,
        address: tuple[str, int],
        fleet: Fleet,
        assembler: ExpositionAssembler,
        security: WebSecurity | None = None,
        routes: Mapping[str, JsonRoute] | None = None,
        robot_documents: Callable[[dict[str, Any]], dict[str, Any]] | None = None,
        on_scrape: Callable[[str], None] | None = None,
        render_timing: RenderTiming | None = None,
    ) -> None:
        """Serve `fleet` on `address` ('' host for every interface; IPv6 when the host has a colon).

        `/metrics` is written by `assembler`; `routes` are JSON paths of other outputs (the events, the
        maintenance windows), each answering its path and those below it; `robot_documents` adds to the
        robots' documents what other outputs know of them (their maintenance); `on_scrape` hears of every
        `/metrics` request as it begins, by its client's address and user agent (`render_ahead`);
        `render_timing` times the fleet's series rendered for each.
        """
        if ":" in address[0]:
            self.address_family = socket.AF_INET6
        self.fleet = fleet
        self.assembler = assembler
        self.routes = dict(routes or {})
        self.robot_documents = robot_documents or (lambda document: document)
        self.on_scrape = on_scrape or (lambda scraper: None)
        self.render_timing = render_timing or RenderTiming()
        self.security = security or WebSecurity()
        self.connections = threading.BoundedSemaphore(MAX_CONNECTIONS)
        self.slots = threading.BoundedSemaphore(MAX_CONCURRENT_REQUESTS)
        self.status_page = resources.files("overseer.serve.status_page").joinpath("index.html").read_bytes()
        self.page_files: dict[str, PageFile] = load_page_files()
        super().__init__(address, _Handler)

    @property
    def url(self) -> str:
        """The base URL the server answers on."""
        host, port = self.server_address[:2]
        shown = "127.0.0.1" if host in ("", "0.0.0.0") else str(host)
        scheme = "https" if self.security.tls is not None else "http"
        return f"{scheme}://{'[' + shown + ']' if ':' in shown else shown}:{port}"

    def process_request(self, request: Any, client_address: Any) -> None:
        """Hand the connection to a thread of its own, or close it when `MAX_CONNECTIONS` are open."""
        if not self.connections.acquire(blocking=False):
            log.debug("closing a connection from %s: %d connections open", client_address, MAX_CONNECTIONS)
            self.shutdown_request(request)
            return
        try:
            super().process_request(request, client_address)
        except BaseException:
            self.connections.release()
            raise

    def process_request_thread(self, request: Any, client_address: Any) -> None:
        """Serve one connection in its thread, then free its place."""
        try:
            super().process_request_thread(request, client_address)
        finally:
            self.connections.release()

    def finish_request(self, request: Any, client_address: Any) -> None:
        """Serve one connection, inside TLS when the web config asks for it."""
        context = self.security.tls
        if context is None:
            _Handler(request, client_address, self)
            return
        connection = _accept_tls(context, request, client_address)
        if connection is not None:
            try:
                _Handler(connection, client_address, self)
            finally:
                connection.close()

    def handle_error(self, request: Any, client_address: Any) -> None:
        """Log a connection's failure: one debug line when the client went away, a traceback otherwise."""
        error = sys.exc_info()[1]
        if isinstance(error, ConnectionError | TimeoutError | ssl.SSLError):
            log.debug("connection from %s ended: %s", client_address, error)
        else:
            log.exception("error serving %s", client_address)


def _accept_tls(context: ssl.SSLContext, sock: socket.socket, client: Any) -> ssl.SSLSocket | None:
    """`sock` inside TLS once the handshake completes within the deadline; None when it does not.

    A client speaking plain HTTP gets a plain 400 saying so, as Go's servers answer, and is closed.
    """
    deadline = time.monotonic() + REQUEST_TIMEOUT_SECONDS
    try:
        sock.settimeout(REQUEST_TIMEOUT_SECONDS)
        first = sock.recv(1, socket.MSG_PEEK)
        if first != _TLS_HANDSHAKE_RECORD:
            if first:
                sock.sendall(_NOT_TLS_ANSWER)
            log.debug("closing a connection from %s that does not speak TLS", client)
            return None
        connection = context.wrap_socket(sock, server_side=True, do_handshake_on_connect=False)
    except OSError as error:
        log.debug("connection from %s ended before TLS: %s", client, error)
        return None
    try:
        connection.setblocking(False)
        while True:
            left = deadline - time.monotonic()
            try:
                connection.do_handshake()
                break
            except ssl.SSLWantReadError:
                ready = select.select([connection], [], [], max(left, 0))[0]
            except ssl.SSLWantWriteError:
                ready = select.select([], [connection], [], max(left, 0))[1]
            if not ready:
                raise TimeoutError("TLS handshake not completed in time")
        connection.settimeout(REQUEST_TIMEOUT_SECONDS)
        return connection
    except OSError as error:  # ssl.SSLError and TimeoutError are ones
        log.debug("TLS handshake with %s failed: %s", client, error)
        connection.close()
        return None


class _TimedStream(io.RawIOBase):
    """A connection as a raw stream whose reads and writes must all be done by `deadline` (monotonic).

    A socket timeout bounds each read or write alone; this bounds their sum, so a client that sends or
    takes one byte at a time cannot hold a thread for longer than the deadline.
    """

    def __init__(self, sock: socket.socket) -> None:
        """Read from and write to `sock`; the deadline is set per request."""
        self._sock = sock
        self.deadline = time.monotonic() + REQUEST_TIMEOUT_SECONDS

    def readable(self) -> bool:
        """It can be read."""
        return True

    def writable(self) -> bool:
        """It can be written."""
        return True

    def readinto(self, buffer: WriteableBuffer) -> int:
        """Read what arrives before the deadline into `buffer`."""
        self._sock.settimeout(self._left())
        return self._sock.recv_into(buffer)

    def write(self, data: ReadableBuffer) -> int:
        """Send all of `data` before the deadline.

        Each send hands the kernel all that is left, so it takes as much as the socket's buffer holds:
        every send lets go of the interpreter lock and, while another thread keeps the interpreter busy
        (the ingest), waits up to 5 ms to take it back: sends of 64 kB each made a 20 MB answer take
        1.8 s beside a busy thread, against 0.35 s now (0.15 s alone).
        """
        view = memoryview(data).cast("B")
        while view:
            self._sock.settimeout(self._left())
            view = view[self._sock.send(view) :]
        return len(memoryview(data).cast("B"))

    def _left(self) -> float:
        left = self.deadline - time.monotonic()
        if left <= 0:
            raise TimeoutError("request or answer not transferred in time")
        return left


class _Handler(BaseHTTPRequestHandler):
    server: OverseerServer
    protocol_version = "HTTP/1.1"
    server_version = "overseer"
    _stream: _TimedStream

    def setup(self) -> None:
        self.connection = self.request
        self._stream = _TimedStream(self.connection)
        self.rfile = io.BufferedReader(self._stream)
        self.wfile = self._stream  # type: ignore[assignment]  # unbuffered, as StreamRequestHandler's

    def handle_one_request(self) -> None:
        self._stream.deadline = time.monotonic() + REQUEST_TIMEOUT_SECONDS
        super().handle_one_request()

    def do_GET(self) -> None:
        self._serve(head_only=False)

    def do_HEAD(self) -> None:
        self._serve(head_only=True)

    def do_POST(self) -> None:
        self._serve(head_only=False)

    def do_DELETE(self) -> None:
        self._serve(head_only=False)

    def do_PUT(self) -> None:
        self._serve(head_only=False)

    def _serve(self, head_only: bool) -> None:
        if not self.server.slots.acquire(timeout=REQUEST_TIMEOUT_SECONDS):
            self._send(503, b"too many concurrent requests\n", "text/plain; charset=utf-8", head_only)
            return
        try:
            if self.server.security.authorized(self.headers.get("Authorization")):
                try:
                    self._route(head_only)
                except FleetPartUnavailable as error:
                    self._json(503, {"error": f"part of the fleet is unavailable: {error}"}, head_only)
            else:
                log.debug("basic auth refused for %s", self.address_string())
                challenge = ("WWW-Authenticate", f'Basic realm="{REALM}"')
                self._send(401, b"Unauthorized\n", "text/plain; charset=utf-8", head_only, extra=(challenge,))
        finally:
            self.server.slots.release()

    def _route(self, head_only: bool) -> None:
        path = urlsplit(self.path).path
        route = self._json_route(path)
        if route is not None:
            self._answer_route(*route, head_only)
        elif self.command not in ("GET", "HEAD"):
            self._json(405, {"error": f"{self.command} is not answered at {path!r}"}, head_only)
        elif path == "/metrics":
            self._metrics(head_only)
        elif path == "/-/healthy" or path == "/-/ready":
            self._send(200, b"OK\n", "text/plain; charset=utf-8", head_only)
        elif path == ROBOTS_PATH or path == ROBOTS_PATH + "/":
            self._robots(head_only)
        elif path.startswith(ROBOTS_PATH + "/"):
            self._robot(unquote(path[len(ROBOTS_PATH) + 1 :]), head_only)
        elif path == COMPONENTS_PATH:
            self._components(head_only)
        elif path.startswith(STATIC_PREFIX) and path[len(STATIC_PREFIX) :] in self.server.page_files:
            page_file = self.server.page_files[path[len(STATIC_PREFIX) :]]
            self._send(
                200, page_file.body, page_file.content_type, head_only, compressible=True, extra=PAGE_HEADERS
            )
        elif path == "/favicon.ico":
            icon = self.server.page_files[FAVICON]
            self._send(200, icon.body, icon.content_type, head_only, compressible=True, extra=PAGE_HEADERS)
        elif path in ("/", "/index.html"):
            self._send(
                200, self.server.status_page, "text/html; charset=utf-8", head_only, extra=PAGE_HEADERS
            )
        else:
            self._json(404, {"error": f"no such path {path!r}"}, head_only)

    def _robots(self, head_only: bool) -> None:
        try:
            query = parse_robot_query(parse_qs(urlsplit(self.path).query))
        except ApiQueryError as error:
            self._json(400, {"error": str(error)}, head_only)
            return
        self._json(200, self.server.robot_documents(self.server.fleet.robots_document(query)), head_only)

    def _robot(self, name: str, head_only: bool) -> None:
        document = self.server.fleet.robot_document(name)
        if document is None:
            self._json(404, {"error": f"unknown robot {name!r}"}, head_only)
        else:
            self._json(200, self.server.robot_documents(document), head_only)

    def _json_route(self, path: str) -> tuple[JsonRoute, str] | None:
        """The route answering `path` and what of the path is past its own."""
        for prefix, route in self.server.routes.items():
            if path == prefix or path.startswith(prefix + "/"):
                return route, unquote(path[len(prefix) + 1 :])
        return None

    def _answer_route(self, route: JsonRoute, rest: str, head_only: bool) -> None:
        length_text = self.headers.get("Content-Length", "0")
        if not length_text.isdigit():
            self._json(400, {"error": "Content-Length: expected a number of bytes"}, head_only)
            return
        length = int(length_text)
        if length > MAX_BODY_BYTES:
            self.close_connection = True  # the body is left unread
            self._json(413, {"error": f"body: at most {MAX_BODY_BYTES} bytes"}, head_only)
            return
        body = self.rfile.read(length) if length else b""
        request = ApiRequest(
            self.command,
            rest,
            urlsplit(self.path).query,
            body,
            self.server.security.user(self.headers.get("Authorization")),
            dict(self.headers.items()),
        )
        status, document = route(request)
        self._json(status, document, head_only)

    def _components(self, head_only: bool) -> None:
        try:
            query = parse_component_query(parse_qs(urlsplit(self.path).query))
        except ApiQueryError as error:
            self._json(400, {"error": str(error)}, head_only)
            return
        self._json(200, self.server.fleet.components_document(query), head_only)

    def _metrics(self, head_only: bool) -> None:
        self.server.on_scrape(f"{self.client_address[0]} {self.headers.get('User-Agent', '')}")
        fmt = negotiate_format(self.headers.get("Accept"))
        parts = self.server.render_timing.timed(self.server.fleet.exposition_parts)
        # Written as the strings it is made of: joined, a 10,000-robot answer would be held twice over.
        if accepts_gzip(self.headers.get("Accept-Encoding")):
            body = self.server.assembler.gzip_body(parts, fmt)
            self._send_body(200, body, fmt.content_type, head_only, encoding="gzip")
        else:
            body = self.server.assembler.text_body(parts, fmt)
            self._send_body(200, body, fmt.content_type, head_only)
        length = body.length
        del parts, body  # freed before the trim, which hands what they held back with the rest
        trim_after_answer(length)

    def _json(self, status: int, document: dict[str, Any], head_only: bool) -> None:
        body = json.dumps(document, ensure_ascii=False, allow_nan=False).encode("utf-8")
        self._send(status, body, "application/json; charset=utf-8", head_only, compressible=True)

    def _send(
        self,
        status: int,
        body: bytes,
        content_type: str,
        head_only: bool = False,
        compressible: bool = False,
        extra: tuple[tuple[str, str], ...] = (),
        encoding: str | None = None,
    ) -> None:
        """Answer `body`; gzipped here when `compressible` and the client takes it, or already `encoding`."""
        if compressible and encoding is None and accepts_gzip(self.headers.get("Accept-Encoding")):
            body = gzip.compress(body, compresslevel=1)
            encoding = "gzip"
        self._send_body(status, Body(len(body), iter((body,))), content_type, head_only, extra, encoding)

    def _send_body(
        self,
        status: int,
        body: Body,
        content_type: str,
        head_only: bool = False,
        extra: tuple[tuple[str, str], ...] = (),
        encoding: str | None = None,
    ) -> None:
        """Answer `body`'s strings, one after the other, already `encoding` when said."""
        self._stream.deadline = time.monotonic() + REQUEST_TIMEOUT_SECONDS
        self.send_response(status)
        self.send_header("Content-Type", content_type)
        self.send_header("Content-Length", str(body.length))
        if encoding:
            self.send_header("Content-Encoding", encoding)
        self.send_header("Cache-Control", "no-store")
        for name, value in extra:
            self.send_header(name, value)
        self.end_headers()
        if not head_only:
            for string in body.strings:
                self.wfile.write(string)

    def end_headers(self) -> None:
        for name, value in self.server.security.headers:
            self.send_header(name, value)
        super().end_headers()

    def log_message(self, format: str, *args: Any) -> None:
        log.debug("%s %s", self.address_string(), format % args)
