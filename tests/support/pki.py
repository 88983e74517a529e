"""Certificates for TLS tests, made by `openssl` for each run.

A CA, a server certificate for IP 127.0.0.1, a client certificate, and a client certificate from another CA.
"""

from __future__ import annotations

import subprocess
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class Pki:
    """Certificates and keys for one test run (PEM files)."""

    directory: Path
    ca: Path
    server_cert: Path
    server_key: Path
    client_cert: Path
    client_key: Path
    client_pem: Path  # certificate and key in one file
    rogue_cert: Path  # a client certificate from another CA
    rogue_key: Path


_EXTENSIONS = """
[ca]
basicConstraints = critical, CA:TRUE
keyUsage = critical, keyCertSign, cRLSign
subjectKeyIdentifier = hash
[server]
basicConstraints = critical, CA:FALSE
keyUsage = critical, digitalSignature, keyEncipherment
extendedKeyUsage = serverAuth
subjectAltName = IP:127.0.0.1
subjectKeyIdentifier = hash
authorityKeyIdentifier = keyid, issuer
[client]
basicConstraints = critical, CA:FALSE
keyUsage = critical, digitalSignature, keyEncipherment
extendedKeyUsage = clientAuth
subjectKeyIdentifier = hash
authorityKeyIdentifier = keyid, issuer
"""


def openssl(directory: Path, *args: str) -> None:
    """Run `openssl` in `directory`."""
    subprocess.run(["openssl", *args], cwd=directory, check=True, capture_output=True, timeout=60)


def make_leaf(directory: Path, name: str, ca: str, kind: str) -> None:
    """`name`.crt and `name`.key, signed by `ca`, with the `kind` (server or client) extensions."""
    openssl(
        directory,
        *("req", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes"),
        *("-subj", f"/CN={name}", "-keyout", f"{name}.key", "-out", f"{name}.csr"),
    )
    openssl(
        directory,
        *("x509", "-req", "-in", f"{name}.csr", "-CA", f"{ca}.crt", "-CAkey", f"{ca}.key"),
        *("-CAcreateserial", "-days", "2", "-extfile", "extensions.cnf", "-extensions", kind),
        *("-out", f"{name}.crt"),
    )


def make_pki(directory: Path) -> Pki:
    """A CA with a server and a client certificate, and a client certificate of another CA."""
    (directory / "extensions.cnf").write_text(_EXTENSIONS)
    # `req -x509` takes its extensions from -config; the same file serves both commands.
    (directory / "openssl.cnf").write_text("[req]\ndistinguished_name = dn\n[dn]\n" + _EXTENSIONS)
    for name in ("ca", "other-ca"):
        openssl(
            directory,
            *("req", "-x509", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes"),
            *("-days", "2", "-subj", f"/CN=Overseer test {name}", "-config", "openssl.cnf"),
            *("-extensions", "ca", "-keyout", f"{name}.key", "-out", f"{name}.crt"),
        )
    make_leaf(directory, "server", "ca", "server")
    make_leaf(directory, "client", "ca", "client")
    make_leaf(directory, "rogue", "other-ca", "client")
    client_pem = directory / "client.pem"
    client_pem.write_bytes((directory / "client.crt").read_bytes() + (directory / "client.key").read_bytes())
    d = directory
    return Pki(
        d, d / "ca.crt", d / "server.crt", d / "server.key", d / "client.crt", d / "client.key", client_pem,
        d / "rogue.crt", d / "rogue.key",
    )  # fmt: skip
