"""/metrics answers each format a scraper asks for, as Prometheus specifies content negotiation.

Unit tests read the `Accept` headers each Prometheus version sends; HTTP tests ask a real server for each
format, plain and gzip, and read OpenMetrics back with prometheus-client's strict parser; one test has
Debian's Prometheus scrape a recording target to learn the header it really sends.
"""

from __future__ import annotations

import http.server
import subprocess
import threading
import time
import urllib.request
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import ClassVar

import pytest

from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import FleetModel
from overseer.serve.exposition_formats import OPENMETRICS, TEXT, ExpositionFormat
from overseer.serve.http import OverseerServer
from overseer.serve.negotiation import accepts_gzip, negotiate_format
from support.oracle import parse_openmetrics
from support.rendering import gunzip_one_member
from testbed.model_server import serving
from testbed.ports import free_port
from testbed.processes import wait_for
from testbed.prometheus import running_prometheus

PROMETHEUS_2 = (
    "application/openmetrics-text;version=1.0.0,application/openmetrics-text;version=0.0.1;q=0.75,"
    "text/plain;version=0.0.4;q=0.5,*/*;q=0.1"
)
PROMETHEUS_2_NATIVE_HISTOGRAMS = (
    "application/vnd.google.protobuf;proto=io.prometheus.client.MetricFamily;encoding=delimited,"
    "application/openmetrics-text;version=1.0.0;q=0.8,application/openmetrics-text;version=0.0.1;q=0.75,"
    "text/plain;version=0.0.4;q=0.5,*/*;q=0.1"
)
PROMETHEUS_2_49 = (  # scrape_protocols' defaults, weighted by position
    "application/openmetrics-text;version=1.0.0;q=0.5,application/openmetrics-text;version=0.0.1;q=0.4,"
    "text/plain;version=0.0.4;q=0.3,*/*;q=0.2"
)
PROMETHEUS_3 = (
    "application/openmetrics-text;version=1.0.0;escaping=allow-utf-8;q=0.6,"
    "application/openmetrics-text;version=0.0.1;q=0.5,text/plain;version=1.0.0;escaping=allow-utf-8;q=0.4,"
    "text/plain;version=0.0.4;q=0.3,*/*;q=0.2"
)
PROMETHEUS_3_LEGACY_NAMES = PROMETHEUS_3.replace("allow-utf-8", "underscores")
PROMETHEUS_3_DOTS = PROMETHEUS_3.replace("allow-utf-8", "dots")
PROMETHEUS_3_PROTOBUF_FIRST = (
    "application/vnd.google.protobuf;proto=io.prometheus.client.MetricFamily;encoding=delimited;q=0.6,"
    "application/openmetrics-text;version=1.0.0;escaping=allow-utf-8;q=0.5,"
    "application/openmetrics-text;version=0.0.1;q=0.4,text/plain;version=1.0.0;escaping=allow-utf-8;q=0.3,"
    "text/plain;version=0.0.4;q=0.2,*/*;q=0.1"
)
PROMETHEUS_3_TEXT_ONLY = "text/plain;version=1.0.0;escaping=allow-utf-8;q=0.6,*/*;q=0.5"

OPENMETRICS_1 = "application/openmetrics-text; version=1.0.0; charset=utf-8; escaping=underscores"
OPENMETRICS_1_UTF8 = "application/openmetrics-text; version=1.0.0; charset=utf-8; escaping=allow-utf-8"
OPENMETRICS_0_0_1 = "application/openmetrics-text; version=0.0.1; charset=utf-8"
TEXT_0_0_4 = "text/plain; version=0.0.4; charset=utf-8"


@pytest.mark.parametrize(
    ("accept", "content_type"),
    [
        (PROMETHEUS_2, OPENMETRICS_1),
        (PROMETHEUS_2_NATIVE_HISTOGRAMS, OPENMETRICS_1),
        (PROMETHEUS_2_49, OPENMETRICS_1),
        (PROMETHEUS_3, OPENMETRICS_1_UTF8),
        (PROMETHEUS_3_LEGACY_NAMES, OPENMETRICS_1),
        (PROMETHEUS_3_PROTOBUF_FIRST, OPENMETRICS_1_UTF8),
        # dots would double our names' underscores: the next format Prometheus offers is taken instead.
        (PROMETHEUS_3_DOTS, OPENMETRICS_0_0_1),
        (PROMETHEUS_3_TEXT_ONLY, "text/plain; version=1.0.0; charset=utf-8; escaping=allow-utf-8"),
        ("text/plain;version=0.0.4", TEXT_0_0_4),
        ("text/plain;version=1.0.0", "text/plain; version=1.0.0; charset=utf-8; escaping=underscores"),
        ("application/openmetrics-text", OPENMETRICS_1),
        (
            "application/openmetrics-text;version=1.0.0;escaping=values",
            OPENMETRICS_1.replace("underscores", "values"),
        ),
        ("application/openmetrics-text;version=1.0.0;escaping=allow-utf8", OPENMETRICS_1_UTF8),
        # q-values decide, not the order in the header
        ("text/plain;version=0.0.4;q=0.9,application/openmetrics-text;version=1.0.0;q=0.5", TEXT_0_0_4),
        ("application/openmetrics-text;q=0, text/plain", TEXT_0_0_4),
        ('APPLICATION/OpenMetrics-Text; Version="1.0.0"; Q=1', OPENMETRICS_1),
        # whatever we do not offer falls back to the text format 0.0.4
        ("application/json", TEXT_0_0_4),
        ("application/openmetrics-text;version=2.0.0", TEXT_0_0_4),
        ("text/plain;version=9", TEXT_0_0_4),
        (
            "application/vnd.google.protobuf;proto=io.prometheus.client.MetricFamily;encoding=delimited",
            TEXT_0_0_4,
        ),
        ("application/openmetrics-text;q=banana", TEXT_0_0_4),
        ("application/openmetrics-text;q=2", TEXT_0_0_4),
        ("application/openmetrics-text;version=1.0.0;escaping=<script>", TEXT_0_0_4),
        ("*/*", TEXT_0_0_4),
        ("", TEXT_0_0_4),
        (None, TEXT_0_0_4),
        (",;;=,q=,", TEXT_0_0_4),
    ],
)
def test_each_accept_header_gets_the_format_the_scrape_protocol_says(
    accept: str | None, content_type: str
) -> None:
    assert negotiate_format(accept).content_type == content_type


@pytest.mark.parametrize(
    ("accept_encoding", "gzip_ok"),
    [
        ("gzip", True),
        ("identity", False),
        (None, False),
        ("gzip;q=0", False),
        ("deflate, gzip;q=0.5", True),
        ("*", True),
        ("*;q=0", False),
        ("*, gzip;q=0", False),
        ("br;q=1, x-gzip", True),
    ],
)
def test_gzip_is_used_when_accept_encoding_admits_it(accept_encoding: str | None, gzip_ok: bool) -> None:
    assert accepts_gzip(accept_encoding) is gzip_ok


@contextmanager
def fleet_server() -> Iterator[OverseerServer]:
    """A real server over a small fleet with hostile names."""
    model = FleetModel()
    for robot in ("robot1", 'site "a"/robot\\2', "new\nline"):
        statuses = (
            DiagnosticStatus(2, "/Power/Battery", "Battery low (4 %)", "bat", (("voltage", "11.1 V"),)),
            DiagnosticStatus(0, "/Motor", "ok", "", ()),
        )
        model.apply(robot, DiagnosticArray(0, 0, "", statuses), "dds")
    with serving(model) as server:
        yield server


def fetch(server: OverseerServer, accept: str | None, use_gzip: bool) -> tuple[str, str | None, bytes]:
    """Content-Type, Content-Encoding and the (decompressed) body of GET /metrics."""
    headers = {"Accept-Encoding": "gzip" if use_gzip else "identity"}
    if accept is not None:
        headers["Accept"] = accept
    request = urllib.request.Request(server.url + "/metrics", headers=headers)
    with urllib.request.urlopen(request, timeout=10) as response:
        body = response.read()
        encoding = response.headers["Content-Encoding"]
        content_type = response.headers["Content-Type"]
    return content_type, encoding, gunzip_one_member(body) if encoding == "gzip" else body


@pytest.mark.parametrize("use_gzip", [False, True], ids=["plain", "gzip"])
def test_every_format_is_served_with_its_content_type_plain_and_gzip(use_gzip: bool) -> None:
    with fleet_server() as server:
        answers = {
            accept: fetch(server, accept, use_gzip)
            for accept in (PROMETHEUS_2, PROMETHEUS_3, PROMETHEUS_3_DOTS, PROMETHEUS_3_TEXT_ONLY, None)
        }
    for accept, (content_type, encoding, body) in answers.items():
        assert content_type == negotiate_format(accept).content_type
        assert encoding == ("gzip" if use_gzip else None)
        assert body.endswith(b"# EOF\n") is content_type.startswith("application/openmetrics-text")
    # Text 1.0.0 is text 0.0.4 for legacy names; the OpenMetrics versions are the same bytes too.
    assert answers[PROMETHEUS_3_TEXT_ONLY][2] == answers[None][2]
    assert answers[PROMETHEUS_2][2] == answers[PROMETHEUS_3][2] == answers[PROMETHEUS_3_DOTS][2]


def test_curl_compressed_reads_the_gzip_answer_as_the_plain_one() -> None:
    # curl, like browsers, reads one gzip member only: an answer laid together from many robots'
    # compressed pieces must still be one member, or curl fails (and other clients show one robot).
    with fleet_server() as server:
        _, _, plain = fetch(server, PROMETHEUS_2, use_gzip=False)
        options = ["--silent", "--show-error", "--fail", "--compressed", "-H", f"Accept: {PROMETHEUS_2}"]
        curl = subprocess.run(
            ["curl", *options, server.url + "/metrics"],
            capture_output=True,
            timeout=30,
            check=True,
        )
    assert curl.stdout == plain
    assert plain.count(b"ros_diagnostics_robot_up{") == 3


def test_an_openmetrics_only_request_reads_back_with_the_strict_parser() -> None:
    with fleet_server() as server:
        content_type, _, body = fetch(server, "application/openmetrics-text;version=1.0.0", False)
    assert content_type == OPENMETRICS_1
    families = {family.name: family for family in parse_openmetrics(body.decode("utf-8"))}
    assert families["ros_diagnostics_level_changes"].type == "counter"
    assert families["ros_diagnostics_robot_last_message_timestamp_seconds"].unit == "seconds"
    robots = {sample.labels["robot"] for sample in families["ros_diagnostics_robot_up"].samples}
    assert robots == {"robot1", 'site "a"/robot\\2', "new\nline"}
    assert body.count(b"# EOF") == 1


class _RecordingTarget(http.server.BaseHTTPRequestHandler):
    """A scrape target that remembers the headers of each scrape and answers one sample."""

    seen: ClassVar[list[dict[str, str]]] = []

    def do_GET(self) -> None:
        _RecordingTarget.seen.append(dict(self.headers.items()))
        body = b"# TYPE probe gauge\nprobe 1\n"
        self.send_response(200)
        self.send_header("Content-Type", TEXT_0_0_4)
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, format: str, *args: object) -> None:
        return


@pytest.mark.servers
def test_debians_prometheus_asks_for_openmetrics_and_gzip_and_is_answered_in_openmetrics(
    tmp_path: Path,
) -> None:
    target = http.server.ThreadingHTTPServer(("127.0.0.1", free_port()), _RecordingTarget)
    threading.Thread(target=target.serve_forever, daemon=True).start()
    config = {
        "global": {"scrape_interval": "1s", "scrape_timeout": "1s"},
        "scrape_configs": [
            {"job_name": "probe", "static_configs": [{"targets": [f"127.0.0.1:{target.server_address[1]}"]}]}
        ],
    }
    try:
        with running_prometheus(tmp_path, config):
            wait_for(lambda: _RecordingTarget.seen, 30, message="a scrape")
            time.sleep(0.1)
    finally:
        target.shutdown()
        target.server_close()
    headers = _RecordingTarget.seen[0]
    chosen: ExpositionFormat = negotiate_format(headers["Accept"])
    assert chosen.openmetrics and chosen.version == "1.0.0", headers["Accept"]
    assert accepts_gzip(headers["Accept-Encoding"])
    assert chosen != TEXT and chosen.content_type == OPENMETRICS.content_type
