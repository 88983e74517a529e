"""`overseer maintenance start|list|end`: maintenance windows through a running exporter's API.

It reaches the exporter through `overseer.client`, with the options of `exporter_options`.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable
from typing import Any

from overseer.client.exporter import ExporterClient
from overseer.client.http import ClientError, quote_path
from overseer.commands import Command
from overseer.commands.exporter_options import add_exporter_options, client_of

PATH = "/api/v1/maintenance"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The `start`, `list` and `end` actions, each with the exporter's address and credentials."""
    actions = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
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
    for action in (start, listing, end):
        add_exporter_options(action)


def run(args: argparse.Namespace) -> int:
    """Run one action; 0 when the exporter did all of it, 1 otherwise (said on stderr)."""
    try:
        client = client_of(args, "maintenance")
        if args.action == "list":
            return _list(client, args.active, args.json)
        if args.action == "start":
            return _each(args.robots, lambda robots: client.call("POST", PATH, _window(args, robots)), args)
        return _each(args.windows, lambda key: client.call("DELETE", f"{PATH}/{quote_path(key)}"), args)
    except ClientError as error:
        print(f"overseer maintenance: {error}", file=sys.stderr)
        return 1


def _window(args: argparse.Namespace, robots: str) -> dict[str, Any]:
    body: dict[str, Any] = {"robots": robots, "comment": args.comment}
    body.update({key: getattr(args, key) for key in ("start", "end", "duration") if getattr(args, key)})
    return body


def _list(client: ExporterClient, active_only: bool, raw: bool) -> int:
    document = client.call("GET", PATH)
    windows = [w for w in document.get("windows", []) if w.get("active") or not active_only]
    if raw:
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


def _each(items: list[str], send: Callable[[str], dict[str, Any]], args: argparse.Namespace) -> int:
    """`send` each item and print the window it answers with; 1 when any was refused (said on stderr)."""
    failed = 0
    for item in items:
        try:
            window = send(item)["window"]
        except ClientError as error:
            print(f"overseer maintenance: {item}: {error}", file=sys.stderr)
            failed += 1
            continue
        if args.json:
            print(json.dumps(window, indent=2, ensure_ascii=False))
        else:
            print(_opened_text(window) if args.action == "start" else _ended_text(window))
    return 1 if failed else 0


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


COMMAND = Command(
    "maintenance",
    "start, list and end maintenance windows on a running exporter",
    "Maintenance windows through the exporter's API (writing needs --web.enable-maintenance-api on the "
    "exporter and a user in maintenance.writers).",
    add_arguments,
    run,
)
