"""The `overseer` command: its entry point, and the table of its subcommands (`commands/`, one each)."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from overseer import __version__
from overseer.commands import Command, demo, maintenance, robots, run, simulate
from overseer.config import ConfigError

COMMANDS: tuple[Command, ...] = (
    run.COMMAND,
    simulate.COMMAND,
    demo.COMMAND,
    maintenance.COMMAND,
    robots.COMMAND,
)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the `overseer` console script."""
    parser = parser_of(COMMANDS)
    args = parser.parse_args(argv)
    command: Command | None = getattr(args, "command", None)
    if command is None:
        parser.print_help()
        return 2
    try:
        return command.run(args)
    except ConfigError as error:
        print(f"overseer {command.name}: configuration error: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 0


def parser_of(commands: Sequence[Command]) -> argparse.ArgumentParser:
    """The argument parser of `overseer` with `commands` as its subcommands."""
    parser = argparse.ArgumentParser(
        prog="overseer", description="Fleet-health monitoring for ROS robots: the exporter and its tools."
    )
    parser.add_argument("--version", action="version", version=f"overseer {__version__}")
    subparsers = parser.add_subparsers(metavar="COMMAND")
    for command in commands:
        subparser = subparsers.add_parser(command.name, help=command.help, description=command.description)
        command.add_arguments(subparser)
        subparser.set_defaults(command=command)
    return parser


if __name__ == "__main__":
    sys.exit(main())
