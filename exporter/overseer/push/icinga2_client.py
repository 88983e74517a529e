"""A small client of the Icinga 2 REST API: one kept-alive HTTPS connection, JSON in and out, pipelined.

Standard library only (http.client and ssl). The server's certificate is always verified against
`ca_file`, under `tls_server_name` when the URL's host is not the name in the certificate.
"""

from __future__ import annotations

import base64
import http.client
import json
import socket
import ssl
from typing import Any
from urllib.parse import quote

from overseer.config.icinga2 import Icinga2Config

Reply = tuple[int, Any]  # an HTTP status and the answer's JSON document (None when it has none)


_QUICKACK: int | None = getattr(socket, "TCP_QUICKACK", None)  # Linux's


class Icinga2Error(Exception):
    """A request that did not succeed; `reason` is a short label for metrics (`http_500`, `timeout`...)."""

    def __init__(self, reason: str, text: str, status: int = 0) -> None:
        """Keep the reason label, the readable text and the HTTP status (0: no answer)."""
        super().__init__(text)
        self.reason = reason
        self.status = status


class _Connection(http.client.HTTPSConnection):
    """An HTTPS connection that verifies the certificate under a name other than the host's."""

    def __init__(self, host: str, port: int, context: ssl.SSLContext, server_name: str, timeout: float):
        super().__init__(host, port, context=context, timeout=timeout)
        self._tls_context = context
        self._server_name = server_name

    def connect(self) -> None:
        """Connect, then wrap the socket with TLS for `server_name`."""
        sock = socket.create_connection((self.host, self.port), self.timeout)
        # As http.client's own connect: without it, Nagle and delayed ACKs cost 40 ms a request.
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.sock = self._tls_context.wrap_socket(sock, server_hostname=self._server_name)


class Icinga2Client:
    """Calls the Icinga 2 REST API described by an `Icinga2Config`."""

    def __init__(self, config: Icinga2Config) -> None:
        """Prepare TLS and credentials; nothing is sent yet."""
        self._config = config
        context = ssl.create_default_context(cafile=config.ca_file)
        if config.client_cert:
            context.load_cert_chain(config.client_cert, config.client_key or None)
        self._context = context
        self._headers = {"Accept": "application/json", "Content-Type": "application/json"}
        if config.password:
            token = base64.b64encode(f"{config.username}:{config.password}".encode()).decode()
            self._headers["Authorization"] = f"Basic {token}"
        self._connection: _Connection | None = None

    def close(self) -> None:
        """Drop the connection; the next request opens a new one."""
        if self._connection is not None:
            self._connection.close()
            self._connection = None

    def request(self, method: str, path: str, body: dict[str, Any] | None = None) -> tuple[int, Any]:
        """Send one request; (status, parsed JSON) for any answer, Icinga2Error when there is none.

        GET is sent as POST with `X-HTTP-Method-Override: GET`, as Icinga documents, so it can carry
        a filter in its body.
        """
        data = None if body is None else json.dumps(body).encode()
        headers = self._headers
        if method == "GET" and data is not None:
            method, headers = "POST", {**headers, "X-HTTP-Method-Override": "GET"}
        status, payload = self._exchange(method, path, data, headers)
        return status, _parsed(payload)

    def pipeline(self, path: str, bodies: list[dict[str, Any]]) -> tuple[list[Reply], Icinga2Error | None]:
        """POST every body to `path` in one write, then read the answers in order (HTTP/1.1 pipelining).

        The answers read, as `request` gives them, and the error that ended the reading early (None when
        every answer came). A request, its headers and body sent apart, and its answer cost three waits for
        the interpreter lock, which a busy exporter's other threads hold: a batch costs about one.
        """
        if not bodies:
            return [], None
        host = f"[{self._config.host}]" if ":" in self._config.host else self._config.host  # IPv6
        head = f"POST {path} HTTP/1.1\r\nHost: {host}:{self._config.port}\r\n"
        head += "".join(f"{name}: {value}\r\n" for name, value in self._headers.items())
        requests = []
        for body in bodies:
            data = json.dumps(body).encode()
            requests.append(f"{head}Content-Length: {len(data)}\r\n\r\n".encode() + data)
        answers: list[Reply] = []
        for attempt in (1, 2):  # a kept-alive connection the server closed fails once; retry on a new one
            connection = self._connect()
            kept_alive = connection.sock is not None
            try:
                if not kept_alive:
                    connection.connect()
                sock = connection.sock
                sock.sendall(b"".join(requests))
                reader = _SharedReader(sock.makefile("rb"))
                try:
                    while len(answers) < len(bodies):
                        # Icinga writes each answer apart: left to the kernel's delayed ACK (40 ms), Nagle's
                        # wait on Icinga's side held the batch's answers back about 44 ms a batch.
                        if _QUICKACK is not None:
                            sock.setsockopt(socket.IPPROTO_TCP, _QUICKACK, 1)
                        response = http.client.HTTPResponse(reader)  # type: ignore[arg-type]
                        response.begin()
                        answers.append((response.status, _parsed(response.read())))
                        if response.will_close:
                            break
                finally:
                    reader.release()
            except (http.client.HTTPException, OSError) as error:  # ssl.SSLError among them
                failure = self._failure(error)
                if attempt == 1 and not answers and _stale(kept_alive, error):
                    continue
                return answers, failure
            if response.will_close:
                self.close()
            if len(answers) < len(bodies):  # the server closed the connection after this answer
                return answers, Icinga2Error(
                    "connection", f"{self._config.url} closed the connection after {len(answers)} answers"
                )
            return answers, None
        raise AssertionError("unreachable")

    def fetch(self, path: str) -> tuple[int, bytes]:
        """GET a file as it is (a config stage's `status` or `startup.log`): (status, bytes)."""
        return self._exchange("GET", path, None, {**self._headers, "Accept": "application/octet-stream"})

    def _exchange(
        self, method: str, path: str, data: bytes | None, headers: dict[str, str]
    ) -> tuple[int, bytes]:
        for attempt in (1, 2):  # a kept-alive connection the server closed fails once; retry on a new one
            connection = self._connect()
            kept_alive = connection.sock is not None
            response = None
            try:
                connection.request(method, path, body=data, headers=headers)
                response = connection.getresponse()
                payload = response.read()
            except (http.client.HTTPException, OSError) as error:
                # Once an answer began, Icinga did what was asked: it is not asked twice.
                if attempt == 1 and response is None and _stale(kept_alive, error):
                    self.close()
                    continue
                # Raised unnamed: a local naming it would hold this frame's traceback, which holds the
                # local, a cycle that keeps every caller's frame (a stage's text) until a full collection.
                raise self._failure(error) from None
            if response.getheader("Connection", "").lower() == "close":
                self.close()
            return response.status, payload
        raise AssertionError("unreachable")

    def expect(self, method: str, path: str, body: dict[str, Any] | None = None) -> Any:
        """`request`, with any answer but a 2xx raised as Icinga2Error naming Icinga's own reason."""
        status, document = self.request(method, path, body)
        if 200 <= status < 300:
            return document
        raise Icinga2Error(
            f"http_{status}", f"{method} {path}: HTTP {status}: {error_text(document)}", status
        )

    def _failure(self, error: Exception) -> Icinga2Error:
        """The connection closed, and `error` (a timeout, TLS, or the connection) in Icinga2Error's words."""
        self.close()
        url = self._config.url
        if isinstance(error, TimeoutError):
            return Icinga2Error("timeout", f"no answer from {url} within {self._config.timeout:g}s")
        if isinstance(error, ssl.SSLError):
            return Icinga2Error("tls", f"TLS with {url} failed: {tls_reason(error)}")
        text = getattr(error, "strerror", None) or str(error) or type(error).__name__
        return Icinga2Error("connection", f"cannot reach {url}: {text}")

    def _connect(self) -> _Connection:
        if self._connection is None:
            config = self._config
            self._connection = _Connection(
                config.host, config.port, self._context, config.tls_server_name or config.host, config.timeout
            )
        return self._connection


def _stale(kept_alive: bool, error: Exception) -> bool:
    """Whether `error` may be a kept-alive connection's end, met by a request: worth one try on a new one.

    The server closed it (Icinga 2 closes an idle one; a reload ends the old process's), and a request
    written on it meets that in more ways than one: no answer, a broken pipe, or a TLS error while being
    written or awaiting its answer. A timeout is a server too slow, not a connection gone: sent again,
    it would wait as long.
    """
    return kept_alive and not isinstance(error, TimeoutError)


class _SharedReader:
    """One buffered reader of a connection lent to each answer in turn: closing an answer keeps it open."""

    def __init__(self, reader: Any) -> None:
        self._reader = reader

    def makefile(self, mode: str) -> _SharedReader:
        """What `http.client.HTTPResponse` reads the answer from: this reader."""
        return self

    def readline(self, limit: int = -1) -> bytes:
        """A line of the answer's head."""
        return bytes(self._reader.readline(limit))

    def read(self, amount: int | None = None) -> bytes:
        """Bytes of the answer's body."""
        return bytes(self._reader.read(amount))

    def readinto(self, buffer: Any) -> int:
        """Bytes of the answer's body, into `buffer`."""
        return int(self._reader.readinto(buffer))

    def close(self) -> None:
        """Kept open: the next answer reads on from here."""

    def release(self) -> None:
        """The batch is read: let the connection's socket go when it closes."""
        self._reader.close()


def _parsed(payload: bytes) -> Any:
    """The JSON document of an answer, None when it has none."""
    try:
        return json.loads(payload) if payload else None
    except ValueError:
        return None


def tls_reason(error: ssl.SSLError) -> str:
    """OpenSSL's reason for a TLS error, or Python's words where OpenSSL gave none (an EOF, a reset)."""
    return str(error.reason or str(error) or type(error).__name__)


def error_text(document: Any) -> str:
    """Icinga's explanation in an error answer (its `status`, or the first result's), cut short."""
    text = ""
    if isinstance(document, dict):
        text = str(document.get("status") or "")
        results = document.get("results")
        if not text and isinstance(results, list) and results and isinstance(results[0], dict):
            text = str(results[0].get("status") or "")
            errors = results[0].get("errors")
            if errors:
                text += f" ({'; '.join(map(str, errors))})"
    return " ".join(text.split())[:300] or "no explanation"


def object_path(kind: str, host: str, service: str = "") -> str:
    """`/v1/objects/hosts/<host>` or `/v1/objects/services/<host>!<service>`, percent-encoded."""
    if kind == "hosts":
        return f"/v1/objects/hosts/{quote(host, safe='')}"
    return f"/v1/objects/services/{quote(host + '!' + service, safe='')}"
