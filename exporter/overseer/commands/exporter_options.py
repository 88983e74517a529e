"""The options of every command that talks to a running exporter: its address, TLS, basic auth, timeout.

They are `check_ros_diagnostics`'s (and read the same `CHECK_ROS_DIAGNOSTICS_AUTH` variable), so a
monitoring host that runs the check can run these commands too.
"""

from __future__ import annotations

import argparse

from overseer import __version__
from overseer.client.exporter import ExporterClient, credentials, exporter_url, timeout_seconds
from overseer.client.http import Tls


def add_exporter_options(parser: argparse.ArgumentParser) -> None:
    """The exporter's address, TLS, credentials and timeout, and `--json` to print its answers raw."""
    group = parser.add_argument_group("exporter (the same options as check_ros_diagnostics)")
    group.add_argument("-H", "--hostname", default="", help="exporter host (default: 127.0.0.1)")
    group.add_argument("-p", "--port", default="", help="exporter port (default: 9849)")
    group.add_argument("--url", default="", help="exporter base URL instead of -H/-p")
    group.add_argument("--authorization-file", default="", metavar="FILE", help="first line USER:PASSWORD")
    group.add_argument("-a", "--authorization", default="", metavar="USER:PASSWORD")
    group.add_argument("--ca-file", default="", metavar="FILE", help="CA to verify an https exporter with")
    group.add_argument("--insecure", action="store_true", help="do not verify the exporter's certificate")
    group.add_argument("--client-cert", default="", metavar="FILE", help="client certificate (mutual TLS)")
    group.add_argument("--client-key", default="", metavar="FILE", help="its key, when in a file of its own")
    group.add_argument("-t", "--timeout", default="10", metavar="SECONDS", help="give up after (default 10)")
    group.add_argument("--json", action="store_true", help="print the exporter's JSON answers as they are")


def client_of(args: argparse.Namespace, command: str) -> ExporterClient:
    """The client the options describe, naming `command` to the exporter; ClientError for a bad option."""
    return ExporterClient(
        exporter_url(args.url, args.hostname, args.port),
        timeout_seconds(args.timeout),
        credentials(args.authorization_file, args.authorization),
        Tls(args.ca_file, args.insecure, args.client_cert, args.client_key),
        f"overseer-{command}/{__version__}",
    )
