"""`overseer maintenance start|list|end`, the installed command, against a real exporter.

The exporter runs in the test process (no transport), with basic auth (alice writes, bob reads) and, in
one test, TLS with a required client certificate (made by openssl for the run): the command reaches it
with the check's options.
"""

from __future__ import annotations

import subprocess
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import bcrypt
import pytest

from overseer.app import Exporter
from support.pki import Pki, make_pki
from testbed.in_process import in_process_exporter, publish
from testbed.ports import free_port
from testbed.processes import overseer_command

HASH = bcrypt.hashpw(b"secret", bcrypt.gensalt(rounds=4)).decode()


@contextmanager
def exporter(tmp_path: Path, web_config: str = "", **web: Any) -> Iterator[Exporter]:
    config = tmp_path / "web.yml"
    config.write_text(
        f"{web_config}basic_auth_users:\n  alice: '{HASH}'\n  bob: '{HASH}'\n", encoding="utf-8"
    )
    with in_process_exporter(
        tmp_path,
        web={"config_file": str(config), "enable_maintenance_api": True, **web},
        maintenance={"writers": ["alice"]},
    ) as running:
        publish(running, "site_a/r1", (2, "/Laser", "no scans"))
        yield running


def maintenance(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    """Run `overseer maintenance ARGS` as a user would."""
    return subprocess.run(
        [*overseer_command(), "maintenance", *args],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
        env=env,
    )


def test_start_list_and_end_a_window_with_the_checks_authentication_options(tmp_path: Path) -> None:
    credentials = tmp_path / "alice.auth"
    credentials.write_text("alice:secret\n", encoding="utf-8")
    with exporter(tmp_path) as running:
        url = ("--url", running.server.url, "--authorization-file", str(credentials))
        started = maintenance("start", "site_a/", "-d", "90m", "-c", "battery swap", *url)
        assert started.returncode == 0, started.stderr
        assert started.stdout.startswith("w1: site_a/ in maintenance from ")
        assert "(alice: battery swap)" in started.stdout
        listed = maintenance("list", *url)
        assert listed.returncode == 0, listed.stderr
        header, row = listed.stdout.splitlines()
        assert header.split() == ["ID", "ROBOTS", "STATE", "START", "END", "AUTHOR", "COMMENT"]
        assert row.split()[:3] == ["w1", "site_a/", "active"] and row.endswith("alice          battery swap")
        ended = maintenance("end", "w1", *url)
        assert ended.returncode == 0, ended.stderr
        assert ended.stdout.startswith("w1: ended at ")
        active = maintenance("list", "--active", *url)
    assert active.stdout == "no maintenance windows active now\n"


def test_refusals_are_explained_and_fail(tmp_path: Path) -> None:
    with exporter(tmp_path) as running:
        url = ("--url", running.server.url)
        as_bob = maintenance("start", "robot1", "-d", "1h", "-c", "x", *url, "-a", "bob:secret")
        assert as_bob.returncode == 1
        assert (
            "HTTP 403" in as_bob.stderr and "bob" in as_bob.stderr and "maintenance.writers" in as_bob.stderr
        )
        bad = maintenance("start", "robot1", "--end", "tomorrow", "-c", "x", *url, "-a", "alice:secret")
        assert bad.returncode == 1 and "HTTP 400" in bad.stderr and "end: expected unix seconds" in bad.stderr
        unknown = maintenance("end", "w99", *url, "-a", "alice:secret")
        assert unknown.returncode == 1 and "no maintenance window 'w99'" in unknown.stderr
        anonymous = maintenance("list", *url, env={"PATH": "/usr/bin:/bin"})
        assert anonymous.returncode == 1 and "HTTP 401" in anonymous.stderr
        from_environment = maintenance(
            "list", *url, env={"PATH": "/usr/bin:/bin", "CHECK_ROS_DIAGNOSTICS_AUTH": "bob:secret"}
        )
        assert from_environment.returncode == 0, from_environment.stderr
    unreachable = maintenance("list", "--url", f"http://127.0.0.1:{free_port()}", "-t", "2")
    assert unreachable.returncode == 1 and "connection refused" in unreachable.stderr


@pytest.fixture(scope="module")
def pki(tmp_path_factory: pytest.TempPathFactory) -> Pki:
    """The certificates of this module's TLS test."""
    return make_pki(tmp_path_factory.mktemp("pki"))


def test_tls_with_a_client_certificate(tmp_path: Path, pki: Pki) -> None:
    tls = (
        "tls_server_config:\n"
        f"  cert_file: {pki.server_cert}\n"
        f"  key_file: {pki.server_key}\n"
        "  client_auth_type: RequireAndVerifyClientCert\n"
        f"  client_ca_file: {pki.ca}\n"
    )
    with exporter(tmp_path, tls) as running:
        url = running.server.url
        assert url.startswith("https://")
        common = ("--url", url, "-a", "alice:secret", "--ca-file", str(pki.ca))
        started = maintenance(
            "start", "site_a/r1", "-d", "1h", "-c", "tls", *common, "--client-cert", str(pki.client_pem)
        )
        assert started.returncode == 0, started.stderr
        refused = maintenance("list", *common)  # no client certificate
        assert refused.returncode == 1 and "TLS error with https:" in refused.stderr
        unverified = maintenance(
            "list", "--url", url, "-a", "alice:secret", "--client-cert", str(pki.client_pem)
        )
        assert unverified.returncode == 1 and "certificate verify failed" in unverified.stderr
