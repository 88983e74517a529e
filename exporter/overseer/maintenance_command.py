"""`overseer maintenance start|list|end`: maintenance windows through the exporter's API.

It reaches the exporter as `check_ros_diagnostics` does, with the same options for the address, TLS and
basic auth (and the same `CHECK_ROS_DIAGNOSTICS_AUTH` variable), so a monitoring host that runs the
check can open a window too.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable
from typing import Any

from overseer.check.document import CheckError
from overseer.check.http_client import Tls, get, quote_path
from overseer.check.plugin import credentials, exporter_url, seconds

PATH = "/api/v1/maintenance"


def add_maintenance_parser(commands: Any) -> None:
    """The `maintenance` command and its `start`, `list` and `end` subcommands."""
    maintenance = commands.add_parser(
        "maintenance",
        help="start, list and end maintenance windows on a running exporter",
        description="Maintenance windows through the exporter's API (writing needs "
        "--web.enable-maintenance-api on the exporter and a user in maintenance.writers).",
    )
    actions = maintenance.add_subparsers(dest="action", metavar="ACTION", required=True)
    start = actions.add_parser("start", help="open a window for robots (a name, or a prefix such as site_a/)")
    start.add_argument("robots", nargs="+", metavar="ROBOTS", help="a robot's name, or a prefix ending in /")
    length = start.add_mutually_exclusive_group(required=True)
    length.add_argument("-d", "--duration", help="how long, e.g. 2h or 30m")
    length.add_argument("--end", help="when it ends: RFC 3339 with offset (2026-11-24T06:00:00Z)")
    start.add_argument("--start", help="when it starts (default: now), RFC 3339 with offset")
    start.add_argument("-c", "--comment", required=True, help="why (shown everywhere the window is)")
    listing = actions.add_parser("list", help="list the windows (recurring ones too)")
    listing.add_argument("--active", action="store_true", help="only the windows that hold now")
    end = actions.add_parser("end", help="end one-off windows now")
    end.add_argument("windows", nargs="+", metavar="ID", help="a window's id, as list shows it (w12)")
    for parser in (start, listing, end):
        _add_connection_flags(parser)


def _add_connection_flags(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("exporter (the same options as check_ros_diagnostics)")
    group.add_argument("-H", "--hostname", help="exporter host (default: 127.0.0.1)")
    group.add_argument("-p", "--port", help="exporter port (default: 9849)")
    group.add_argument("--url", help="exporter base URL instead of -H/-p")
    group.add_argument("--authorization-file", metavar="FILE", help="first line USER:PASSWORD")
    group.add_argument("-a", "--authorization", metavar="USER:PASSWORD")
    group.add_argument("--ca-file", metavar="FILE", help="CA to verify an https exporter with")
    group.add_argument("--insecure", action="store_true", help="do not verify the exporter's certificate")
    group.add_argument("--client-cert", metavar="FILE", help="client certificate (mutual TLS)")
    group.add_argument("--client-key", metavar="FILE", help="its key, when in a file of its own")
    group.add_argument("-t", "--timeout", default="10", metavar="SECONDS", help="give up after (default 10)")
    group.add_argument("--json", action="store_true", help="print the exporter's JSON answers as they are")


def run_maintenance(args: argparse.Namespace) -> int:
    """Run one `overseer maintenance` action; 0 when the exporter did all of it, 1 otherwise."""
    try:
        client = _Client(args)
        if args.action == "list":
            return client.show(args.active)
        if args.action == "start":
            return client.start(args)
        return client.end(args.windows)
    except CheckError as error:
        print(f"overseer maintenance: {error}", file=sys.stderr)
        return 1


class _Client:
    """The exporter's maintenance API, reached with the check's options."""

    def __init__(self, args: argparse.Namespace) -> None:
        flags = {
            f"--{name.replace('_', '-')}": value
            for name in ("hostname", "port", "url", "authorization_file", "authorization")
            if (value := getattr(args, name)) is not None
        }
        self.url = exporter_url(flags)
        self.authorization = credentials(flags)
        self.timeout = seconds(args.timeout)
        self.tls = Tls(args.ca_file or "", args.insecure, args.client_cert or "", args.client_key or "")
        self.raw = args.json

    def show(self, active_only: bool) -> int:
        document = self._call("GET", PATH)
        windows = [w for w in document.get("windows", []) if w.get("active") or not active_only]
        if self.raw:
            print(json.dumps({**document, "windows": windows}, indent=2, ensure_ascii=False))
            return 0
        if not windows:
            print("no maintenance windows" + (" active now" if active_only else ""))
            return 0
        print(f"{'ID':<22} {'ROBOTS':<24} {'STATE':<9} {'START':<20} {'END':<20} {'AUTHOR':<14} COMMENT")
        for window in windows:
            print(
                f"{window['id']:<22} {window['robots']:<24} {_state(window):<9} {_time(window['start']):<20} "
                f"{_time(window['end']):<20} {window['author'][:14]:<14} {_one_line(window['comment'])}"
            )
        return 0

    def start(self, args: argparse.Namespace) -> int:
        def open_window(robots: str) -> dict[str, Any]:
            body: dict[str, Any] = {"robots": robots, "comment": args.comment}
            body.update(
                {key: getattr(args, key) for key in ("start", "end", "duration") if getattr(args, key)}
            )
            return self._call("POST", PATH, body)

        return self._each(args.robots, open_window, _opened_text)

    def end(self, keys: list[str]) -> int:
        return self._each(keys, lambda key: self._call("DELETE", f"{PATH}/{quote_path(key)}"), _ended_text)

    def _each(
        self,
        items: list[str],
        send: Callable[[str], dict[str, Any]],
        text: Callable[[dict[str, Any]], str],
    ) -> int:
        """`send` each item and print the window it answers with; 1 when any was refused (said on stderr)."""
        failed = 0
        for item in items:
            try:
                window = send(item)["window"]
            except CheckError as error:
                print(f"overseer maintenance: {item}: {error}", file=sys.stderr)
                failed += 1
                continue
            print(json.dumps(window, indent=2, ensure_ascii=False) if self.raw else text(window))
        return 1 if failed else 0

    def _call(self, method: str, path: str, body: dict[str, Any] | None = None) -> dict[str, Any]:
        """The JSON answer of one request; CheckError with the exporter's own error when it refuses."""
        url = self.url + path
        data = None if body is None else json.dumps(body).encode()
        answer = get(url, self.timeout, self.authorization, self.tls, method, data)
        try:
            document = json.loads(answer.body)
        except ValueError:
            document = None
        if not isinstance(document, dict):
            raise CheckError(f"HTTP {answer.status} {answer.reason} from {url}: the answer is not JSON")
        if not 200 <= answer.status < 300:
            error = str(document.get("error", "no explanation"))
            raise CheckError(f"HTTP {answer.status} from {url}: {error}")
        return document


def _opened_text(window: dict[str, Any]) -> str:
    return (
        f"{window['id']}: {window['robots']} in maintenance from {_time(window['start'])} "
        f"until {_time(window['end'])} ({window['author']}: {_one_line(window['comment'])})"
    )


def _ended_text(window: dict[str, Any]) -> str:
    return f"{window['id']}: ended at {_time(window['end'])} ({window['robots']})"


def _state(window: dict[str, Any]) -> str:
    if window.get("active"):
        return "active"
    if window.get("start", 0) > time.time():
        return "scheduled"
    return "ended"


def _time(at: float) -> str:
    return time.strftime("%Y-%m-%d %H:%M:%SZ", time.gmtime(at))


def _one_line(text: str) -> str:
    return " ".join(str(text).split())
