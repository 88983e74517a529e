"""A real Icinga 2 daemon for tests: temporary directories, loopback REST API, always stopped.

It runs as root with every path (config, data, log, cache, spool, run) moved into a temporary
directory, loads the ITL, the shipped deploy/icinga2 files and a test-only objects file, and
exposes its API on a free loopback port with certificates made by `icinga2 pki`.
"""

from __future__ import annotations

import base64
import json
import ssl
import subprocess
import urllib.request
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from testbed.nagios import PluginResult, join_output, stop_process_group
from testbed.paths import REPO
from testbed.ports import free_port
from testbed.processes import VENV_BIN, wait_for

ICINGA2 = "/usr/sbin/icinga2"
ICINGA2_DEPLOY = REPO / "deploy" / "icinga2"
NODE_NAME = "overseer-test"
API_USER = "overseer-test"
API_PASSWORD = "overseer-test-password"
_DIRECTORIES = ("ConfigDir", "DataDir", "LogDir", "CacheDir", "SpoolDir", "InitRunDir")


def defines(root: Path) -> list[str]:
    """`-D` options that move every Icinga 2 path under `root` and keep it running as root."""
    options = [f"-DConfiguration.{name}={root / name.lower()}" for name in _DIRECTORIES]
    return [
        *options,
        f"-DConfiguration.PidPath={root / 'initrundir' / 'icinga2.pid'}",
        "-DConfiguration.RunAsUser=root",
        "-DConfiguration.RunAsGroup=root",
    ]


def icinga2(root: Path, *args: str, timeout: float = 60.0) -> subprocess.CompletedProcess[str]:
    """Run an `icinga2` command with the paths under `root`."""
    return subprocess.run(
        [ICINGA2, *args, *defines(root)], capture_output=True, text=True, timeout=timeout, check=False
    )


def write_icinga2_config(root: Path, objects: str, api_port: int | None = None) -> Path:
    """A main icinga2.conf under `root`: ITL, checker, the shipped deploy/icinga2 files and `objects`.

    With `api_port`, also the REST API on that loopback port (which needs `make_certificates`).
    PluginContribDir points at the environment's bin directory, so the shipped CheckCommand runs
    this checkout's check_ros_diagnostics.
    """
    for name in _DIRECTORIES:
        (root / name.lower()).mkdir(parents=True, exist_ok=True)
    (root / "objects.conf").write_text(objects, encoding="utf-8")
    main_config = root / "configdir" / "icinga2.conf"
    main_config.write_text(
        f"""const NodeName = "{NODE_NAME}"
const ZoneName = NodeName
const PluginDir = "/usr/lib/nagios/plugins"
const PluginContribDir = "{VENV_BIN}"

include <itl>

object FileLogger "main-log" {{
	path = LogDir + "/icinga2.log"
	severity = "information"
}}
object CheckerComponent "checker" {{ }}
{api_objects(api_port) if api_port is not None else ""}
include "{ICINGA2_DEPLOY}/*.conf"
include "{root / "objects.conf"}"
""",
        encoding="utf-8",
    )
    return main_config


def api_objects(api_port: int) -> str:
    """The objects that serve the REST API on 127.0.0.1:`api_port` to the test's ApiUser."""
    return f"""object Endpoint NodeName {{ }}
object Zone ZoneName {{
	endpoints = [ NodeName ]
}}
object ApiListener "api" {{
	bind_host = "127.0.0.1"
	bind_port = {api_port}
}}
object ApiUser "{API_USER}" {{
	password = "{API_PASSWORD}"
	permissions = [ "*" ]
}}
"""


def make_certificates(root: Path) -> None:
    """A CA and the node's certificate, where the ApiListener looks for them (DataDir/certs)."""
    certs = root / "datadir" / "certs"
    certs.mkdir(parents=True, exist_ok=True)
    key, csr, cert = (certs / f"{NODE_NAME}.{suffix}" for suffix in ("key", "csr", "crt"))
    for args in (
        ("pki", "new-ca"),
        ("pki", "new-cert", "--cn", NODE_NAME, "--key", str(key), "--csr", str(csr)),
        ("pki", "sign-csr", "--csr", str(csr), "--cert", str(cert)),
    ):
        done = icinga2(root, *args)
        assert done.returncode == 0, f"icinga2 {' '.join(args)} failed:\n{done.stdout}{done.stderr}"
    (certs / "ca.crt").write_bytes((root / "datadir" / "ca" / "ca.crt").read_bytes())


@dataclass
class Icinga2:
    """A running Icinga 2 daemon and its REST API."""

    process: subprocess.Popen[bytes]
    root: Path
    api_port: int

    def api(
        self, method: str, path: str, body: dict[str, Any], user: str = API_USER, password: str = API_PASSWORD
    ) -> Any:
        """Call the REST API (GET as POST with X-HTTP-Method-Override, so it can carry a body)."""
        context = ssl.create_default_context(cafile=str(self.root / "datadir" / "certs" / "ca.crt"))
        context.check_hostname = False  # the certificate names the node, not 127.0.0.1
        request = urllib.request.Request(
            f"https://127.0.0.1:{self.api_port}{path}",
            data=json.dumps(body).encode(),
            method="POST",
            headers={"Accept": "application/json", "X-HTTP-Method-Override": method},
        )
        token = base64.b64encode(f"{user}:{password}".encode()).decode()
        request.add_header("Authorization", f"Basic {token}")
        with urllib.request.urlopen(request, context=context, timeout=10) as response:
            return json.load(response)

    @property
    def ca_file(self) -> Path:
        """The CA certificate that signed the API's certificate (issued to NODE_NAME)."""
        return self.root / "datadir" / "certs" / "ca.crt"

    def reschedule(self, host: str, service: str) -> None:
        """Ask for the service's check to run now."""
        self.api(
            "POST",
            "/v1/actions/reschedule-check",
            {"type": "Service", "service": f"{host}!{service}", "force": True},
        )

    def result(self, host: str, service: str) -> PluginResult | None:
        """The service's last check result in plugin format, None before its first check."""
        answer = self.api("GET", "/v1/objects/services", {"service": f"{host}!{service}"})
        last = answer["results"][0]["attrs"]["last_check_result"]
        if last is None:
            return None
        text, _, long_output = last["output"].partition("\n")
        perfdata = " ".join(quote_label(item) for item in last["performance_data"])
        # `state`, not `exit_status`: a passive result (process-check-result) leaves exit_status at 0.
        return PluginResult(int(last["state"]), join_output(text, perfdata, long_output))

    def stop(self) -> None:
        """Stop the daemon (it saves its state and the objects made over the API, as on shutdown)."""
        stop_process_group(self.process)

    def start(self) -> None:
        """Start the stopped daemon again, on the same configuration, state and port."""
        self.process = start_daemon(self.root)
        self.wait_until_up()

    def wait_until_up(self) -> None:
        """Wait until the API answers; RuntimeError with the daemon's output if it exits."""
        wait_for(lambda: api_is_up(self), timeout=60, message="the Icinga 2 API")

    def host_result(self, host: str) -> PluginResult | None:
        """The host's last check result (0 UP, 1 DOWN) and output, None before its first one."""
        attrs = self.api("GET", "/v1/objects/hosts", {"host": host, "attrs": ["last_check_result", "state"]})[
            "results"
        ][0]["attrs"]
        last = attrs["last_check_result"]
        return None if last is None else PluginResult(int(attrs["state"]), last["output"])

    def objects(self, kind: str) -> dict[str, dict[str, Any]]:
        """Every object of `kind` (hosts, services) by full name, with its vars."""
        answer = self.api("GET", f"/v1/objects/{kind}", {"attrs": ["vars"]})
        return {item["name"]: item["attrs"]["vars"] or {} for item in answer["results"]}

    def log(self) -> str:
        """The daemon's main log."""
        return (self.root / "logdir" / "icinga2.log").read_text(encoding="utf-8", errors="replace")


def quote_label(item: str) -> str:
    """A perfdata item with its label quoted, as the check writes it (Icinga 2 drops needless quotes)."""
    return item if item.startswith("'") else "'" + item.replace("=", "'=", 1)


@contextmanager
def running_icinga2(root: Path, objects: str) -> Iterator[Icinga2]:
    """Run Icinga 2 with the shipped definitions and `objects` until the block ends, then stop it."""
    api_port = free_port()
    write_icinga2_config(root, objects, api_port)
    make_certificates(root)
    daemon = Icinga2(start_daemon(root), root, api_port)
    try:
        daemon.wait_until_up()
        yield daemon
    finally:
        daemon.stop()


def start_daemon(root: Path) -> subprocess.Popen[bytes]:
    """Start `icinga2 daemon` on the configuration written under `root`, output to root/daemon.out."""
    log = (root / "daemon.out").open("ab")
    try:
        return subprocess.Popen(
            [ICINGA2, "daemon", "-c", str(root / "configdir" / "icinga2.conf"), *defines(root)],
            stdout=log,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
    finally:
        log.close()


def api_is_up(daemon: Icinga2) -> bool:
    """Whether the API answers; RuntimeError with the daemon's output if it has exited."""
    if daemon.process.poll() is not None:
        output = (daemon.root / "daemon.out").read_text(encoding="utf-8", errors="replace")
        raise RuntimeError(f"icinga2 exited with {daemon.process.returncode}:\n{output}")
    daemon.api("GET", "/v1/status/IcingaApplication", {})
    return True


PUSH_USER = "overseer-push"
PUSH_PASSWORD = "overseer-push-password"
PUSH_API_USER_EXAMPLE = ICINGA2_DEPLOY / "push" / "api-user-overseer.conf"


def push_api_user() -> str:
    """The shipped push ApiUser example, exactly, with the test's password instead of the placeholder."""
    text = PUSH_API_USER_EXAMPLE.read_text(encoding="utf-8")
    assert text.count('password = "change-me"') == 1, "the example's password line changed"
    return text.replace('password = "change-me"', f'password = "{PUSH_PASSWORD}"')


def push_cert_api_user() -> str:
    """The push ApiUser example as a second user, `PUSH_CERT_USER`, authenticated by client certificate."""
    return (
        push_api_user()
        .replace(f'"{PUSH_USER}"', f'"{PUSH_CERT_USER}"', 1)
        .replace(f'password = "{PUSH_PASSWORD}"', f'client_cn = "{PUSH_CERT_USER}"')
    )


PUSH_CERT_USER = "overseer-push-cert"
PUSH_BULK_USER = "overseer-bulk"


def push_bulk_api_user() -> str:
    """The push ApiUser example as user `PUSH_BULK_USER`, its optional config package permissions on."""
    text = push_api_user().replace(f'"{PUSH_USER}"', f'"{PUSH_BULK_USER}"', 1)
    for permission in ('"config/query"', '"config/modify"'):
        assert f"// {permission}," in text, "the example's optional package permissions changed"
        text = text.replace(f"// {permission},", f"{permission},")
    return text


def client_certificate(root: Path, cn: str) -> tuple[Path, Path]:
    """A client certificate and key for `cn`, signed by the CA of the daemon under `root`."""
    directory = root / "client-certs"
    directory.mkdir(exist_ok=True)
    key, csr, cert = (directory / f"{cn}.{suffix}" for suffix in ("key", "csr", "crt"))
    for args in (
        ("pki", "new-cert", "--cn", cn, "--key", str(key), "--csr", str(csr)),
        ("pki", "sign-csr", "--csr", str(csr), "--cert", str(cert)),
    ):
        done = icinga2(root, *args)
        assert done.returncode == 0, f"icinga2 {' '.join(args)} failed:\n{done.stdout}{done.stderr}"
    return cert, key


def push_config(
    directory: Path,
    daemon: Icinga2,
    exporter_id: str,
    interval: str,
    password: str = PUSH_PASSWORD,
    client_cert: tuple[Path, Path] | None = None,
    timeout: str = "10s",
    username: str = PUSH_USER,
) -> Path:
    """An exporter configuration file pushing to `daemon` as the example ApiUser (password in a file).

    With `client_cert` (certificate, key), it authenticates with that certificate instead.
    """
    section: dict[str, str] = {
        "url": f"https://127.0.0.1:{daemon.api_port}",
        "ca_file": str(daemon.ca_file),
        "tls_server_name": NODE_NAME,
        "interval": interval,
        "exporter_id": exporter_id,
        "timeout": timeout,
    }
    if client_cert is None:
        password_file = directory / f"{exporter_id}.password"
        password_file.write_text(password + "\n", encoding="utf-8")
        section.update(username=username, password_file=str(password_file))
    else:
        section.update(client_cert=str(client_cert[0]), client_key=str(client_cert[1]))
    config = directory / f"{exporter_id}.yml"
    config.write_text(json.dumps({"icinga2": section}), encoding="utf-8")
    return config
