"""The check's failure modes, each one UNKNOWN line, against a fake exporter.

A real exporter never answers with a server error, a refused login, a stall or broken JSON, so
these tests (and only these) serve canned answers from a tiny local HTTP server: its test names
say `fake_exporter`. The check runs as a subprocess, as Nagios runs it.
"""

from __future__ import annotations

import json
import socket
import ssl
import subprocess
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import pytest

from support.check_cases import assert_matches_golden
from testbed.nagios import run_check
from testbed.ports import free_port

pytestmark = pytest.mark.servers  # every test here starts real servers or middleware


ROBOT_DOCUMENT = {
    "generated_at": 1700000010.0,
    "robot": "robot1",
    "level": 1,
    "state": "WARN",
    "up": True,
    "last_message": 1700000009.5,
    "transport": "dds",
    "counts": {"ok": 1, "warn": 1, "error": 0, "stale": 0},
    "components": [
        {
            "name": "/Power/Robot Battery",
            "hardware_id": "power1",
            "level": 1,
            "state": "WARN",
            "reported_level": 1,
            "stale": False,
            "message": "Low charge",
            "values": [{"key": "voltage", "value": "11.36"}, {"key": "percentage", "value": "18.0"}],
            "last_update": 1700000009.5,
            "level_changes": 1,
        },
        {
            "name": "/Power",
            "hardware_id": "",
            "level": 0,
            "state": "OK",
            "reported_level": 0,
            "stale": False,
            "message": "OK",
            "values": [],
            "last_update": 1700000009.5,
            "level_changes": 0,
        },
    ],
}
GOOD_ANSWER = (200, "application/json", json.dumps(ROBOT_DOCUMENT).encode())
CREDENTIALS = "Basic b3BlcmF0b3I6czNjcmV0"  # operator:s3cret


class Recorder:
    """What the fake exporter answers, and the requests it saw."""

    def __init__(self, status: int, content_type: str, body: bytes, require_auth: bool = False) -> None:
        """Answer every GET with `status` and `body` (401 without the right credentials if `require_auth`)."""
        self.answer = (status, content_type, body)
        self.require_auth = require_auth
        self.requests: list[tuple[str, str]] = []


def handler_for(recorder: Recorder) -> type[BaseHTTPRequestHandler]:
    """A request handler that answers as `recorder` says and records each request."""

    class Handler(BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            recorder.requests.append((self.path, self.headers.get("Authorization", "")))
            status, content_type, body = recorder.answer
            if recorder.require_auth and self.headers.get("Authorization") != CREDENTIALS:
                status, content_type, body = 401, "text/plain", b"login required"
            self.send_response(status)
            self.send_header("Content-Type", content_type)
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, format: str, *args: object) -> None:
            """Keep the test output quiet."""

    return Handler


@contextmanager
def fake_exporter(recorder: Recorder, tls: ssl.SSLContext | None = None) -> Iterator[str]:
    """Serve `recorder`'s answer on a loopback port (in TLS with `tls`); yields the base URL."""
    server = ThreadingHTTPServer(("127.0.0.1", 0), handler_for(recorder))
    if tls is not None:
        server.socket = tls.wrap_socket(server.socket, server_side=True)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"{'https' if tls else 'http'}://127.0.0.1:{server.server_address[1]}"
    finally:
        server.shutdown()
        server.server_close()
        thread.join(10)


@contextmanager
def silent_listener() -> Iterator[int]:
    """A port that accepts connections into its backlog and never answers; yields the port."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as listener:
        listener.bind(("127.0.0.1", 0))
        listener.listen(8)
        yield listener.getsockname()[1]


def test_unreachable_exporter_is_unknown() -> None:
    result = run_check("-H", "127.0.0.1", "-p", str(free_port()), "-r", "robot1")
    assert_matches_golden("exporter_unreachable", result)


def test_fake_exporter_that_never_answers_times_out_unknown_within_the_timeout() -> None:
    with silent_listener() as port:
        started = time.monotonic()
        result = run_check("-p", str(port), "-r", "robot1", "-t", "1.5")
        elapsed = time.monotonic() - started
    assert 1.5 <= elapsed < 10
    assert_matches_golden("fake_exporter_timeout", result)


@pytest.mark.parametrize(
    ("golden", "answer"),
    [
        ("fake_exporter_http_500", (500, "text/plain", b"boom")),
        ("fake_exporter_http_401", (401, "text/plain", b"who are you")),
        ("fake_exporter_http_403", (403, "text/plain", b"not you")),
        ("fake_exporter_malformed_json", (200, "application/json", b'{"robot": "robot1", ')),
        ("fake_exporter_unexpected_json", (200, "application/json", b'{"robots": []}')),
        ("fake_exporter_404_not_an_exporter", (404, "text/html", b"<h1>Not Found</h1>")),
        ("fake_exporter_unknown_robot", (404, "application/json", b'{"error": "unknown robot \'robot1\'"}')),
    ],
)
def test_fake_exporter_failures_are_one_unknown_line(golden: str, answer: tuple[int, str, bytes]) -> None:
    with fake_exporter(Recorder(*answer)) as url:
        result = run_check("--url", url, "-r", "robot1")
    assert result.output.count("\n") == 1
    assert_matches_golden(golden, result)


def read_request_and_hang_up(listener: socket.socket) -> None:
    """Accept one connection, read the request, close without a word."""
    connection, _ = listener.accept()
    with connection:
        connection.recv(65536)


def test_fake_exporter_that_hangs_up_without_answering_is_unknown() -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as listener:
        listener.bind(("127.0.0.1", 0))
        listener.listen(1)
        thread = threading.Thread(target=read_request_and_hang_up, args=(listener,), daemon=True)
        thread.start()
        result = run_check("-p", str(listener.getsockname()[1]), "-r", "robot1")
        thread.join(10)
    assert_matches_golden("fake_exporter_hangs_up", result)


def test_fake_exporter_behind_basic_auth_gets_the_credentials() -> None:
    recorder = Recorder(*GOOD_ANSWER, require_auth=True)
    with fake_exporter(recorder) as url:
        refused = run_check("--url", url, "-r", "robot1", "-a", "operator:wrong")
        accepted = run_check("--url", url, "-r", "robot1", "-a", "operator:s3cret", "-v", "--perfdata-values")
    assert refused.state == 3
    assert refused.output.startswith("UNKNOWN - authentication refused by http://127.0.0.1:")
    assert recorder.requests[-1] == ("/api/v1/robots/robot1", CREDENTIALS)
    assert_matches_golden("fake_exporter_verbose_with_values", accepted)


def test_fake_exporter_gets_robot_names_percent_encoded() -> None:
    recorder = Recorder(404, "application/json", b'{"error": "unknown robot"}')
    with fake_exporter(recorder) as url:
        result = run_check("--url", url + "/prefix/", "-r", "site a/robot7")
    assert result.state == 3
    assert recorder.requests == [("/prefix/api/v1/robots/site%20a/robot7", "")]


@pytest.fixture(scope="module")
def certificate(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A self-signed certificate for 127.0.0.1 and its key, made by openssl."""
    directory = tmp_path_factory.mktemp("tls")
    cert, key = directory / "cert.pem", directory / "key.pem"
    subprocess.run(
        [
            "openssl",
            "req",
            "-x509",
            "-newkey",
            "rsa:2048",
            "-nodes",
            "-days",
            "2",
            "-subj",
            "/CN=127.0.0.1",
            "-addext",
            "subjectAltName=IP:127.0.0.1",
            "-keyout",
            str(key),
            "-out",
            str(cert),
        ],
        check=True,
        capture_output=True,
        timeout=60,
    )
    return cert, key


def test_fake_exporter_over_https_is_verified_against_the_ca_file(certificate: tuple[Path, Path]) -> None:
    cert, key = certificate
    context = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
    context.load_cert_chain(cert, key)
    with fake_exporter(Recorder(*GOOD_ANSWER), tls=context) as url:
        verified = run_check("--url", url, "-r", "robot1", "--ca-file", str(cert))
        unverified = run_check("--url", url, "-r", "robot1")
        insecure = run_check("--url", url, "-r", "robot1", "--insecure")
    assert verified.state == insecure.state == 1
    assert verified.output == insecure.output
    assert unverified.state == 3
    assert "certificate verify failed" in unverified.output
    assert unverified.output.count("\n") == 1


def test_fake_exporter_very_verbose_output_ends_with_the_url_read() -> None:
    with fake_exporter(Recorder(*GOOD_ANSWER)) as url:
        result = run_check("--url", url, "-r", "robot1", "-vv")
    assert result.state == 1
    size = len(GOOD_ANSWER[2])
    assert result.output.endswith(f"\nRead {url}/api/v1/robots/robot1 (HTTP 200, {size} bytes)\n")
