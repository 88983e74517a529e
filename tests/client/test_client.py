"""The exporter's HTTP client: URLs, requests, answers, and the options the check and the commands share."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from overseer.client.exporter import AUTH_VARIABLE, ExporterClient, credentials, exporter_url, timeout_seconds
from overseer.client.http import (
    ClientError,
    Tls,
    connect,
    parse_answer,
    parse_url,
    quote_path,
    request_bytes,
)
from support.garbage import left_in_cycles
from testbed.ports import free_port


@pytest.mark.parametrize(
    ("url", "parts"),
    [
        ("http://127.0.0.1:9849/api/v1/robots/r", (False, "127.0.0.1", 9849, "/api/v1/robots/r")),
        ("https://o.example/x", (True, "o.example", 443, "/x")),
        ("HTTP://o.example", (False, "o.example", 80, "/")),
        ("http://[::1]:81/p", (False, "::1", 81, "/p")),
    ],
)
def test_parse_url(url: str, parts: tuple[bool, str, int, str]) -> None:
    target = parse_url(url)
    assert (target.tls, target.host, target.port, target.path) == parts


@pytest.mark.parametrize("url", ["http://:80/", "http://h:0/", "http://h:x/", "h:80"])
def test_parse_url_rejects_bad_urls(url: str) -> None:
    with pytest.raises(ClientError, match="invalid URL"):
        parse_url(url)


def test_quote_path_keeps_slashes_and_encodes_the_rest() -> None:
    assert quote_path("site_a/robot 7?ü") == "site_a/robot%207%3F%C3%BC"


def test_request_sends_basic_auth_and_host() -> None:
    request = request_bytes(parse_url("http://[::1]:81/api"), "user:pass")
    assert request.startswith(b"GET /api HTTP/1.0\r\nHost: [::1]:81\r\n")
    assert b"\r\nAuthorization: Basic dXNlcjpwYXNz\r\n" in request
    assert request.endswith(b"\r\n\r\n")


def test_parse_answer_honours_content_length() -> None:
    answer = parse_answer(b"HTTP/1.0 404 Not Found\r\nContent-Length: 2\r\n\r\n{}garbage", "u")
    assert (answer.status, answer.reason, answer.body) == (404, "Not Found", b"{}")


@pytest.mark.parametrize(
    ("raw", "message"),
    [
        (b"", "no HTTP answer from u"),
        (b"SSH-2.0-OpenSSH\r\n\r\n", "no HTTP answer from u"),
        (b"HTTP/1.1 200 OK\r\nContent-Length: 10\r\n\r\n{}", "answer from u cut short: 2 of 10 bytes"),
    ],
)
def test_parse_answer_rejects_what_is_not_a_whole_http_answer(raw: bytes, message: str) -> None:
    with pytest.raises(ClientError, match=message):
        parse_answer(raw, "u")


@pytest.mark.parametrize(
    ("url", "host", "port", "expected"),
    [
        ("", "", "", "http://127.0.0.1:9849"),
        ("", "::1", "81", "http://[::1]:81"),
        ("https://overseer.example/proxy/", "", "", "https://overseer.example/proxy"),
    ],
)
def test_the_exporters_url_comes_from_url_or_host_and_port(
    url: str, host: str, port: str, expected: str
) -> None:
    assert exporter_url(url, host, port) == expected


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        (("http://a", "b", ""), "give either --url or -H/-p, not both"),
        (("", "", "99999"), "invalid port '99999'"),
        (("ftp://a", "", ""), "invalid URL"),
    ],
)
def test_a_bad_address_is_one_client_error(arguments: tuple[str, str, str], message: str) -> None:
    with pytest.raises(ClientError, match=message):
        exporter_url(*arguments)


def test_credentials_come_from_a_file_the_command_line_or_the_environment(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    secret = tmp_path / "auth"
    secret.write_text("alice:from file\nignored\n", encoding="utf-8")
    monkeypatch.setenv(AUTH_VARIABLE, "bob:from environment")
    assert credentials(str(secret)) == "alice:from file"
    assert credentials(given="carol:given") == "carol:given"
    assert credentials() == "bob:from environment"
    with pytest.raises(ClientError, match="not both"):
        credentials(str(secret), "carol:given")
    monkeypatch.setenv(AUTH_VARIABLE, "no colon")
    with pytest.raises(ClientError, match=f"^{AUTH_VARIABLE}: expected USER:PASSWORD$"):  # never the secret
        credentials()


@pytest.mark.parametrize(
    ("text", "ok"), [("10", True), ("0.5", True), ("0", False), ("x", False), ("1e9", False)]
)
def test_the_timeout_is_positive_seconds_below_a_day(text: str, ok: bool) -> None:
    if ok:
        assert timeout_seconds(text) == float(text)
    else:
        with pytest.raises(ClientError, match="invalid --timeout"):
            timeout_seconds(text)


def test_an_unreachable_exporter_is_one_client_error_naming_its_url() -> None:
    client = ExporterClient("http://127.0.0.1:9", timeout=2)  # the discard port: nothing listens
    with pytest.raises(
        ClientError, match=r"exporter unreachable at http://127\.0\.0\.1:9/api/v1/maintenance"
    ):
        client.call("GET", "/api/v1/maintenance")
    assert (
        client.url_of("/api/v1/robots", "site_a/robot 7")
        == "http://127.0.0.1:9/api/v1/robots/site_a/robot%207"
    )


def test_a_refused_connection_leaves_no_reference_cycle() -> None:
    target = parse_url(f"http://127.0.0.1:{free_port()}/metrics")
    # The error named by a local of the frame its traceback holds: a cycle.
    assert left_in_cycles(lambda: connect(target, time.monotonic() + 5, Tls()), OSError) == []
