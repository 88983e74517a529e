"""TLS, client certificates and basic auth on the endpoint, from an exporter-toolkit web config.

Certificates are made by `openssl` for each run: a CA, a server certificate for IP 127.0.0.1, a client
certificate, and a client certificate from another CA. The exporter, the check and Prometheus run as
real processes against each other.
"""

from __future__ import annotations

import base64
import socket
import ssl
import subprocess
import time
import urllib.error
import urllib.request
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path

import bcrypt
import pytest
from prometheus_client.parser import text_string_to_metric_families

from overseer.check import main as check_main
from overseer.config import ConfigError
from overseer.serve.web_config import BasicAuth, load_web_config
from support.pki import Pki, make_pki
from testbed.nagios import run_check
from testbed.ports import free_port, fresh_domain_id
from testbed.processes import Exporter, overseer_command, running_simulator, spawn, wait_for
from testbed.prometheus import running_prometheus

USER, PASSWORD = "prometheus", "correct horse battery staple"
HEADERS_BLOCK = (
    "http_server_config:\n  headers:\n    X-Frame-Options: deny\n    X-Content-Type-Options: nosniff\n"
)


@pytest.fixture(scope="module")
def pki(tmp_path_factory: pytest.TempPathFactory) -> Pki:
    """The certificates of this module's tests."""
    return make_pki(tmp_path_factory.mktemp("pki"))


@pytest.fixture(scope="module")
def password_hash() -> str:
    """PASSWORD hashed as htpasswd -B does, at the toolkit's example cost."""
    return bcrypt.hashpw(PASSWORD.encode(), bcrypt.gensalt(rounds=10)).decode()


def web_config_text(pki: Pki, password_hash: str, client_auth: str = "RequireAndVerifyClientCert") -> str:
    """An exporter-toolkit web config with TLS, client certificates, basic auth and two headers."""
    return (
        "tls_server_config:\n"
        f"  cert_file: {pki.server_cert.name}\n"  # relative: read from the file's directory
        f"  key_file: {pki.server_key.name}\n"
        f"  client_auth_type: {client_auth}\n"
        f"  client_ca_file: {pki.ca}\n"
        "  min_version: TLS12\n"
        f"{HEADERS_BLOCK}"
        f"basic_auth_users:\n  {USER}: '{password_hash}'\n"
    )


# --- The file ---


def test_toolkit_file_gives_tls_with_verified_client_certificates_auth_and_headers(
    pki: Pki, password_hash: str
) -> None:
    path = pki.directory / "web.yml"
    path.write_text(web_config_text(pki, password_hash))
    security = load_web_config(path)
    assert security.tls is not None
    assert security.tls.verify_mode == ssl.CERT_REQUIRED
    assert security.tls.minimum_version == ssl.TLSVersion.TLSv1_2
    assert security.headers == (("X-Frame-Options", "deny"), ("X-Content-Type-Options", "nosniff"))
    assert security.basic_auth is not None
    assert security.authorized(basic(USER, PASSWORD))
    assert not security.authorized(basic(USER, "wrong"))


def test_no_file_and_an_empty_file_are_plain_http_without_auth(tmp_path: Path) -> None:
    empty = tmp_path / "web.yml"
    empty.write_text("")
    for security in (load_web_config(None), load_web_config(empty)):
        assert security.tls is None and security.basic_auth is None
        assert security.authorized(None)


def test_optional_client_certificate_is_verified_when_given(pki: Pki, password_hash: str) -> None:
    path = pki.directory / "optional.yml"
    path.write_text(web_config_text(pki, password_hash, "VerifyClientCertIfGiven"))
    tls = load_web_config(path).tls
    assert tls is not None and tls.verify_mode == ssl.CERT_OPTIONAL


TLS_KEYS = "tls_server_config: {cert_file: server.crt, key_file: server.key, "
BAD_FILES = [
    ("- a list", "top level: expected a mapping, got ['a list']"),
    ("tls_server_config: [", "is not valid YAML"),
    ("rate_limit: {interval: 1s}", "rate_limit: unknown key"),
    (
        "tls_server_config:\n  cert_file: server.crt\n",
        "tls_server_config.key_file: expected a file name, got None",
    ),
    (
        "tls_server_config: {cert_file: server.crt, key_file: server.key, client_auth_type: Sometimes}",
        "tls_server_config.client_auth_type: expected one of NoClientCert, VerifyClientCertIfGiven, "
        "RequireAndVerifyClientCert, got 'Sometimes'",
    ),
    (
        TLS_KEYS + "client_auth_type: RequireAnyClientCert}",
        "tls_server_config.client_auth_type: 'RequireAnyClientCert' (a certificate nobody verifies)",
    ),
    (
        "tls_server_config: {cert_file: server.crt, key_file: server.key, "
        "client_auth_type: RequireAndVerifyClientCert}",
        "tls_server_config.client_ca_file: expected a file name, got None",
    ),
    (
        "tls_server_config: {cert_file: server.crt, key_file: server.key, client_ca_file: ca.crt}",
        "tls_server_config.client_ca_file: set, but client_auth_type is NoClientCert",
    ),
    (
        "tls_server_config: {cert_file: server.crt, key_file: server.key, min_version: TLS10}",
        "tls_server_config.min_version: TLS10 is not supported; use TLS12 or TLS13",
    ),
    (
        TLS_KEYS + "min_version: TLS13, max_version: TLS12}",
        "tls_server_config.max_version: must not be below min_version, got 'TLS12'",
    ),
    (
        TLS_KEYS + "cipher_suites: [TLS_AES_128_GCM_SHA256]}",
        "tls_server_config.cipher_suites: not supported by Overseer",
    ),
    (
        "tls_server_config: {cert_file: missing.crt, key_file: server.key}",
        "tls_server_config.cert_file, key_file: cannot load",
    ),
    (
        "tls_server_config: {cert_file: server.crt, key_file: client.key}",
        "KEY_VALUES_MISMATCH",
    ),
    (
        "http_server_config: {headers: {X-Powered-By: overseer}}",
        "http_server_config.headers.X-Powered-By: cannot be set",
    ),
    (
        "http_server_config: {headers: {X-Frame-Options: allow}}",
        "http_server_config.headers.X-Frame-Options: expected one of deny, sameorigin, got 'allow'",
    ),
    ("http_server_config: {http2: maybe}", "http_server_config.http2: expected true or false, got 'maybe'"),
    ("basic_auth_users: {alice: hunter2}", "basic_auth_users.alice: expected a bcrypt hash"),
    ("basic_auth_users: {'a:b': x}", "basic_auth_users: expected user names without ':', got 'a:b'"),
]


@pytest.mark.parametrize(("text", "message"), BAD_FILES, ids=[m[:40] for _, m in BAD_FILES])
def test_bad_file_is_one_error_naming_the_key_and_value(pki: Pki, text: str, message: str) -> None:
    path = pki.directory / "bad.yml"
    path.write_text(text)
    with pytest.raises(ConfigError) as raised:
        load_web_config(path)
    assert message in str(raised.value)
    assert str(raised.value).startswith("web.config_file")
    assert "\n" not in str(raised.value)
    assert "hunter2" not in str(raised.value)  # a plain-text password is never echoed


def test_a_file_that_is_not_yaml_is_named_by_place_without_quoting_its_lines(
    pki: Pki, password_hash: str
) -> None:
    path = pki.directory / "broken.yml"
    path.write_text(f"basic_auth_users:\n  {USER}: '{password_hash}'\n\tbroken: [\n")
    with pytest.raises(ConfigError) as raised:
        load_web_config(path)
    assert str(raised.value) == f"web.config_file: {str(path)!r} is not valid YAML (line 3, column 1)"


@pytest.mark.servers
def test_run_with_a_bad_web_config_exits_2_with_one_line(tmp_path: Path) -> None:
    path = tmp_path / "web.yml"
    path.write_text("tls_server_config:\n  cert_file: nowhere.crt\n  key_file: nowhere.key\n")
    result = subprocess.run(
        [*overseer_command(), "run", f"--web.config.file={path}", "--web.listen-address=127.0.0.1:0"],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=tmp_path,
    )
    assert result.returncode == 2
    assert not (tmp_path / "overseer-events.db").exists()  # a configuration error opens nothing
    assert result.stderr.splitlines() == [
        f"overseer run: configuration error: web.config_file {str(path)!r}: tls_server_config.cert_file, "
        f"key_file: cannot load {str(tmp_path / 'nowhere.crt')!r} with {str(tmp_path / 'nowhere.key')!r}: "
        "No such file or directory"
    ]


# --- Basic auth ---


def basic(user: str, password: str | bytes) -> str:
    """An Authorization header value."""
    raw = password if isinstance(password, bytes) else password.encode()
    return "Basic " + base64.b64encode(user.encode() + b":" + raw).decode()


class CountingBcrypt:
    """bcrypt.checkpw, counting its calls."""

    def __init__(self) -> None:
        """Count from zero."""
        self.calls = 0
        self._checkpw = bcrypt.checkpw

    def __call__(self, password: bytes, hashed: bytes) -> bool:
        """Check as bcrypt does."""
        self.calls += 1
        return self._checkpw(password, hashed)


@pytest.fixture
def counting_bcrypt(monkeypatch: pytest.MonkeyPatch) -> CountingBcrypt:
    """bcrypt.checkpw replaced by a counting wrapper."""
    counter = CountingBcrypt()
    monkeypatch.setattr(bcrypt, "checkpw", counter)
    return counter


def test_a_verified_password_is_cached_and_a_wrong_one_never_is(
    password_hash: str, counting_bcrypt: CountingBcrypt
) -> None:
    auth = BasicAuth({USER: password_hash.encode()})
    assert auth.check(basic(USER, PASSWORD))
    started = time.perf_counter()
    assert all(auth.check(basic(USER, PASSWORD)) for _ in range(1000))
    assert time.perf_counter() - started < 0.5  # a bcrypt at cost 10 alone takes about 70 ms
    assert counting_bcrypt.calls == 1
    assert not auth.check(basic(USER, PASSWORD + "!"))
    assert not auth.check(basic(USER, PASSWORD + "!"))
    assert counting_bcrypt.calls == 3
    assert auth.check(basic(USER, PASSWORD)) and counting_bcrypt.calls == 3


def test_an_unknown_user_costs_a_bcrypt_as_a_known_one_does(
    password_hash: str, counting_bcrypt: CountingBcrypt
) -> None:
    auth = BasicAuth({USER: password_hash.encode()})
    assert not auth.check(basic("mallory", PASSWORD))
    assert counting_bcrypt.calls == 1


@pytest.mark.parametrize(
    "header",
    [
        None,
        "",
        "Bearer abc",
        "Basic",
        "Basic !!!not-base64!!!",
        "Basic " + base64.b64encode(b"no-colon").decode(),
        "Basic " + base64.b64encode(b"\xff\xfe:" + PASSWORD.encode()).decode(),
        basic(USER, "x" * 73),  # longer than bcrypt reads
        basic(USER, PASSWORD + "\x00"),
        basic(USER.upper(), PASSWORD),
    ],
)
def test_malformed_or_wrong_credentials_are_refused_without_an_error(
    password_hash: str, header: str | None
) -> None:
    assert not BasicAuth({USER: password_hash.encode()}).check(header)


# --- The exporter, the check and Prometheus over TLS ---


@dataclass
class Secured:
    """A running exporter behind TLS with required client certificates and basic auth."""

    exporter: Exporter
    pki: Pki
    password_file: Path
    wrong_password_file: Path


def client_context(pki: Pki, cert: Path | None = None, key: Path | None = None) -> ssl.SSLContext:
    """A TLS client context trusting the test CA, presenting the client certificate unless `cert` says."""
    context = ssl.create_default_context(cafile=pki.ca)
    context.load_cert_chain(cert or pki.client_cert, key or pki.client_key)
    return context


def fetch(
    url: str, context: ssl.SSLContext | None, authorization: str | None = None, timeout: float = 10
) -> tuple[int, dict[str, str], bytes]:
    """Status, headers and body of GET `url`."""
    request = urllib.request.Request(url, headers={"Authorization": authorization} if authorization else {})
    try:
        with urllib.request.urlopen(request, context=context, timeout=timeout) as response:
            return response.status, dict(response.headers), response.read()
    except urllib.error.HTTPError as error:
        return error.code, dict(error.headers), error.read()


@contextmanager
def secured_exporter(tmp_path: Path, domain: int, web_config: Path, *extra: str) -> Iterator[Exporter]:
    """`overseer run` with `web_config`, once it answers over TLS with the right credentials."""
    port = free_port()
    args = [
        *overseer_command(),
        "run",
        f"--web.listen-address=127.0.0.1:{port}",
        f"--dds.domain={domain}",
        "--dds.loopback-only",
        f"--web.config.file={web_config}",
        *extra,
    ]
    log_path = tmp_path / f"exporter-{port}.log"
    exporter = Exporter(spawn(args, log_path, cwd=tmp_path), log_path, f"https://127.0.0.1:{port}")
    try:
        yield exporter
    finally:
        exporter.stop()


@pytest.fixture(scope="module")
def secured(tmp_path_factory: pytest.TempPathFactory, pki: Pki, password_hash: str) -> Iterator[Secured]:
    """The exporter (logging at debug level) and a two-robot fleet, once both robots are up."""
    tmp_path = tmp_path_factory.mktemp("secured")
    web_config = pki.directory / "secured.yml"
    web_config.write_text(web_config_text(pki, password_hash))
    password_file = tmp_path / "password"
    password_file.write_text(PASSWORD)
    wrong_password_file = tmp_path / "wrong-password"
    wrong_password_file.write_text("not " + PASSWORD)
    domain = fresh_domain_id()
    with ExitStack() as stack:
        exporter = stack.enter_context(secured_exporter(tmp_path, domain, web_config, "--log.level=debug"))
        stack.enter_context(running_simulator(tmp_path, domain, "--robots=2", "--warn=0", "--error=0"))
        context = client_context(pki)

        def both_robots_up() -> bool:
            if exporter.process.poll() is not None:
                raise AssertionError(exporter.log())
            try:
                status, _, body = fetch(exporter.url + "/api/v1/robots", context, basic(USER, PASSWORD), 2)
            except (OSError, urllib.error.URLError):
                return False
            return status == 200 and body.count(b'"up": true') == 2

        wait_for(both_robots_up, 60, message="both robots up behind TLS")
        yield Secured(exporter, pki, password_file, wrong_password_file)


@pytest.mark.servers
def test_client_certificate_and_password_get_metrics_with_the_configured_headers(secured: Secured) -> None:
    status, headers, body = fetch(
        secured.exporter.url + "/metrics", client_context(secured.pki), basic(USER, PASSWORD)
    )
    assert status == 200
    assert (headers["X-Frame-Options"], headers["X-Content-Type-Options"]) == ("deny", "nosniff")
    families = {family.name for family in text_string_to_metric_families(body.decode())}
    assert {"ros_diagnostics_level", "ros_diagnostics_robot_up"} <= families


@pytest.mark.servers
@pytest.mark.parametrize("path", ["/metrics", "/-/healthy", "/api/v1/robots", "/", "/no/such/path"])
@pytest.mark.parametrize(
    "authorization", [None, basic(USER, "wrong"), basic("mallory", PASSWORD), "Basic garbage"]
)
def test_wrong_or_missing_password_is_401_with_a_basic_challenge_on_every_path(
    secured: Secured, path: str, authorization: str | None
) -> None:
    status, headers, body = fetch(secured.exporter.url + path, client_context(secured.pki), authorization)
    assert (status, headers["WWW-Authenticate"], body) == (401, 'Basic realm="overseer"', b"Unauthorized\n")
    assert headers["X-Frame-Options"] == "deny"


# TLS 1.3 checks the client's certificate after the client has finished its handshake: the refusal is
# an alert when the client reads first, or a connection torn down under its first write.
REFUSALS = ("alert certificate required", "alert unknown ca", "EOF occurred in violation of protocol")


def refused(url: str, context: ssl.SSLContext | None) -> str:
    """How GET `url` fails with `context`, as the error's text; fails the test when any HTTP answer comes."""
    try:
        status, _, body = fetch(url, context, basic(USER, PASSWORD))
    except (OSError, urllib.error.URLError) as error:
        return str(error)
    raise AssertionError(f"not refused: HTTP {status}, {body[:200]!r}")


@pytest.mark.servers
def test_no_client_certificate_is_refused_in_the_handshake(secured: Secured) -> None:
    context = ssl.create_default_context(cafile=secured.pki.ca)
    error = refused(secured.exporter.url + "/metrics", context)
    assert any(refusal in error for refusal in REFUSALS), error


@pytest.mark.servers
def test_a_client_certificate_from_another_ca_is_refused(secured: Secured) -> None:
    context = client_context(secured.pki, secured.pki.rogue_cert, secured.pki.rogue_key)
    error = refused(secured.exporter.url + "/metrics", context)
    assert any(refusal in error for refusal in REFUSALS), error


@pytest.mark.servers
def test_a_client_that_does_not_trust_the_server_refuses_it(secured: Secured) -> None:
    context = ssl.create_default_context()  # the system's CAs do not know the test CA
    context.load_cert_chain(secured.pki.client_cert, secured.pki.client_key)
    assert "CERTIFICATE_VERIFY_FAILED" in refused(secured.exporter.url + "/metrics", context)


@pytest.mark.servers
def test_plain_http_to_the_tls_port_is_refused_with_400_and_no_data(secured: Secured) -> None:
    plain_url = secured.exporter.url.replace("https://", "http://") + "/metrics"
    status, _, body = fetch(plain_url, None, basic(USER, PASSWORD))
    assert (status, body) == (400, b"Client sent an HTTP request to an HTTPS server.\n")


@pytest.mark.servers
def test_silent_connections_do_not_hold_up_other_clients(secured: Secured) -> None:
    host, port = secured.exporter.url.removeprefix("https://").split(":")
    with ExitStack() as stack:
        for index in range(20):
            silent = stack.enter_context(socket.create_connection((host, int(port)), timeout=5))
            if index % 2:
                silent.sendall(b"\x16\x03\x01")  # the start of a TLS record, then nothing
        started = time.monotonic()
        status, _, _ = fetch(
            secured.exporter.url + "/-/healthy", client_context(secured.pki), basic(USER, PASSWORD)
        )
        assert status == 200
        assert time.monotonic() - started < 2


@pytest.mark.servers
def test_check_speaks_tls_with_client_certificate_and_password_from_a_file(secured: Secured) -> None:
    secured.password_file.with_name("auth").write_text(f"{USER}:{PASSWORD}\n")
    common = ("--url", secured.exporter.url, "-r", "robot1", "--ca-file", str(secured.pki.ca))
    result = run_check(
        *common,
        *("--client-cert", str(secured.pki.client_cert), "--client-key", str(secured.pki.client_key)),
        *("--authorization-file", str(secured.password_file.with_name("auth"))),
    )
    assert (result.state, result.output.split(" | ")[0]) == (0, "OK - robot1: 15 components OK")
    combined = run_check(*common, "--client-cert", str(secured.pki.client_pem), "-a", f"{USER}:{PASSWORD}")
    assert combined == result


@pytest.mark.servers
def test_check_takes_the_password_from_the_environment(
    secured: Secured, monkeypatch: pytest.MonkeyPatch
) -> None:
    args = ["--url", secured.exporter.url, "-r", "robot2", "--ca-file", str(secured.pki.ca)]
    args += ["--client-cert", str(secured.pki.client_pem)]
    monkeypatch.setenv("CHECK_ROS_DIAGNOSTICS_AUTH", f"{USER}:{PASSWORD}")
    assert run_check(*args).state == 0
    monkeypatch.setenv("CHECK_ROS_DIAGNOSTICS_AUTH", f"{USER}:wrong")
    result = run_check(*args)
    assert result.state == 3
    url = f"{secured.exporter.url}/api/v1/robots/robot2"
    assert result.output == f"UNKNOWN - authentication refused by {url}: HTTP 401 Unauthorized\n"


@pytest.mark.servers
@pytest.mark.parametrize(
    ("extra", "expected"),
    [
        ((), "UNKNOWN - TLS error with {url}/api/v1/robots/robot1: certificate verify failed"),
        (
            ("--ca-file", "{ca}"),
            "UNKNOWN - TLS error with {url}/api/v1/robots/robot1: ",
        ),
        (("--ca-file", "{ca}", "--client-cert", "{rogue}"), "UNKNOWN - cannot use --client-cert '{rogue}'"),
        (
            ("--ca-file", "/nonexistent"),
            "UNKNOWN - cannot use --ca-file '/nonexistent': No such file or directory",
        ),
        (
            ("--authorization-file", "/nonexistent"),
            "UNKNOWN - cannot read --authorization-file '/nonexistent'",
        ),
    ],
)
def test_check_failures_in_tls_are_one_unknown_line_naming_the_cause(
    secured: Secured, extra: tuple[str, ...], expected: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("CHECK_ROS_DIAGNOSTICS_AUTH", f"{USER}:{PASSWORD}")
    values = {"url": secured.exporter.url, "ca": str(secured.pki.ca), "rogue": str(secured.pki.rogue_cert)}
    args = [arg.format(**values) for arg in extra]
    result = run_check("--url", secured.exporter.url, "-r", "robot1", *args)
    assert result.state == 3
    assert result.output.startswith(expected.format(**values))
    assert result.output.count("\n") == 1
    assert PASSWORD not in result.output


def test_check_help_offers_credentials_from_a_file_and_the_environment_and_warns_about_a(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert check_main(["--help"]) == 3
    text = " ".join(capsys.readouterr().out.split())
    for option in (
        "--authorization-file=FILE",
        "CHECK_ROS_DIAGNOSTICS_AUTH",
        "--client-cert=FILE",
        "--client-key=FILE",
    ):
        assert option in text
    assert "Other users of the host can read command lines" in text


@pytest.mark.servers
def test_check_never_prints_a_password_it_cannot_use(secured: Secured, tmp_path: Path) -> None:
    path = tmp_path / "auth"
    path.write_text("just-a-secret-without-user\n")
    result = run_check("--url", secured.exporter.url, "-r", "robot1", "--authorization-file", str(path))
    assert result.output == f"UNKNOWN - --authorization-file {str(path)!r}: expected USER:PASSWORD\n"


@pytest.mark.servers
def test_prometheus_scrapes_the_protected_endpoint(secured: Secured, tmp_path: Path) -> None:
    pki, target = secured.pki, secured.exporter.url.removeprefix("https://")

    def job(name: str, password_file: Path, client_certificate: bool = True) -> dict[str, object]:
        tls: dict[str, str] = {"ca_file": str(pki.ca)}
        if client_certificate:
            tls |= {"cert_file": str(pki.client_cert), "key_file": str(pki.client_key)}
        return {
            "job_name": name,
            "scheme": "https",
            "static_configs": [{"targets": [target]}],
            "tls_config": tls,
            "basic_auth": {"username": USER, "password_file": str(password_file)},
        }

    config = {
        "global": {"scrape_interval": "1s", "scrape_timeout": "1s", "evaluation_interval": "1s"},
        "scrape_configs": [
            job("overseer", secured.password_file),
            job("wrong-password", secured.wrong_password_file),
            job("no-client-certificate", secured.password_file, client_certificate=False),
        ],
    }
    with running_prometheus(tmp_path, config) as prometheus:

        def scraped() -> dict[str, float] | None:
            up = {r["metric"]["job"]: float(r["value"][1]) for r in prometheus.query("up")}
            return up if len(up) == 3 else None

        robots = wait_for(
            lambda: prometheus.query('ros_diagnostics_robot_up{job="overseer"} == 1'), 60, message="robots"
        )
        up = wait_for(scraped, 30, message="three scrape jobs")
    assert up == {"overseer": 1.0, "wrong-password": 0.0, "no-client-certificate": 0.0}
    assert sorted(r["metric"]["robot"] for r in robots) == ["robot1", "robot2"]


@pytest.mark.servers
def test_no_secret_reaches_the_log(secured: Secured, password_hash: str) -> None:
    for password in (PASSWORD, "guessed-wrong-password"):
        fetch(secured.exporter.url + "/metrics", client_context(secured.pki), basic(USER, password))
    log = secured.exporter.log()
    assert "GET /metrics" in log  # the debug log does record requests
    for secret in (PASSWORD, "guessed-wrong-password", password_hash, basic(USER, PASSWORD).split()[1]):
        assert secret not in log
    assert "Traceback" not in log
