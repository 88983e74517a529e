"""`overseer robots list|retire|reload|check`: the fleet's robots through a running exporter, its inventory.

`list`, `retire` and `reload` reach the exporter through `overseer.client` (the options of
`exporter_options`); `check` reads an inventory file here, as `promtool check config` does, so a file can
be checked before it is deployed.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Any
from urllib.parse import quote

from overseer.client.http import ClientError
from overseer.commands import Command
from overseer.commands.exporter_options import add_exporter_options, client_of
from overseer.inventory.file import InventoryError, load_inventory

ROBOTS_PATH = "/api/v1/robots"
RETIREMENTS_PATH = "/api/v1/retirements"
RELOAD_PATH = "/-/reload"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The `list`, `retire`, `reload` and `check` actions."""
    actions = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    listing = actions.add_parser("list", help="list the robots the exporter follows, with their labels")
    listing.add_argument(
        "--label", action="append", default=[], metavar="NAME=VALUE", help="only robots with this label"
    )
    listing.add_argument("--down", action="store_true", help="only the robots that are down")
    retire = actions.add_parser("retire", help="forget robots that are down and not in the inventory")
    retire.add_argument("robots", nargs="+", metavar="ROBOT", help="a robot's name, as list shows it")
    retire.add_argument("-c", "--comment", default="", help="why (recorded in the event history)")
    reload = actions.add_parser("reload", help="have the exporter read its inventory file again")
    for action in (listing, retire, reload):
        add_exporter_options(action)
    check = actions.add_parser("check", help="check an inventory file, as the exporter would read it")
    check.add_argument("file", metavar="FILE", help="the inventory file")


def run(args: argparse.Namespace) -> int:
    """Run one action; 0 when all of it was done, 1 otherwise (said on stderr)."""
    if args.action == "check":
        return _check(args.file)
    try:
        client = client_of(args, "robots")
        if args.action == "list":
            return _list(client.call("GET", _robots_path(args.label)), args.down, args.json)
        if args.action == "reload":
            client.call("POST", RELOAD_PATH)
            print("inventory reloaded")
            return 0
        failed = 0
        for robot in args.robots:
            try:
                answer = client.call("POST", RETIREMENTS_PATH, {"robot": robot, "comment": args.comment})
            except ClientError as error:
                print(f"overseer robots retire: {robot}: {error}", file=sys.stderr)
                failed += 1
                continue
            print(json.dumps(answer, ensure_ascii=False) if args.json else f"{robot}: {answer['message']}")
        return 1 if failed else 0
    except ClientError as error:
        print(f"overseer robots {args.action}: {error}", file=sys.stderr)
        return 1


def _robots_path(labels: list[str]) -> str:
    query = "&".join("label=" + quote(label, safe="=") for label in labels)
    return ROBOTS_PATH + ("?" + query if query else "")


def _check(path: str) -> int:
    try:
        inventory = load_inventory(path)
    except InventoryError as error:
        print(f"overseer robots check: {error}", file=sys.stderr)
        return 1
    robots = inventory.robots.values()
    expected = sum(len(robot.expected) for robot in robots)
    print(f"{path}: {len(robots)} robots, {expected} expected components in all: OK")
    return 0


def _list(document: dict[str, Any], down_only: bool, raw: bool) -> int:
    robots = [robot for robot in document.get("robots", []) if not (down_only and robot.get("up"))]
    if raw:
        print(json.dumps({**document, "robots": robots}, indent=2, ensure_ascii=False))
        return 0
    if not robots:
        print("no robots" + (" down" if down_only else ""))
        return 0
    print(f"{'ROBOT':<28} {'STATE':<6} {'UP':<46} {'INVENTORY':<9} LABELS")
    for robot in robots:
        labels = ",".join(f"{name}={value}" for name, value in sorted(robot.get("labels", {}).items()))
        listed = "listed" if robot.get("listed") else "-"
        print(f"{robot['robot']:<28} {robot['state']:<6} {_presence(robot):<46} {listed:<9} {labels}")
    return 0


def _presence(robot: dict[str, Any]) -> str:
    if robot.get("up"):
        return "up"
    if robot.get("last_message") is None:
        return "down: never heard"
    since = time.strftime("%Y-%m-%d %H:%M:%SZ", time.gmtime(robot["last_message"]))
    why = "publisher left" if robot.get("down_reason") == "publisher_left" else "silent"
    return f"down ({why}) since {since}"


COMMAND = Command(
    "robots",
    "list, retire and reload the robots of a running exporter; check an inventory file",
    "The fleet's robots through the exporter's API (retire needs --web.enable-maintenance-api and a user "
    "in maintenance.writers, reload --web.enable-lifecycle), and checking an inventory file before use.",
    add_arguments,
    run,
)
