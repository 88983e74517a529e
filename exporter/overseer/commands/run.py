"""`overseer run`: the exporter, configured by a file and by a flag for each key of the configuration."""

from __future__ import annotations

import argparse
import logging
import sys

from overseer.commands import Command
from overseer.commands.signals import StopSignals
from overseer.config import ConfigError, load_config
from overseer.config.loading import ALL_OPTIONS
from overseer.config.options import add_flags, naming_the_flag, overrides
from overseer.garbage_collection import collect_in_large_batches
from overseer.heap_trim import shape_heap, trim_heap_every
from overseer.log_format import configure_logging

log = logging.getLogger("overseer")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """`--config.file`, and the flag of every configuration key that has one."""
    parser.add_argument("--config.file", dest="config_file", metavar="PATH", help="YAML configuration file")
    add_flags(parser, ALL_OPTIONS)


def run(args: argparse.Namespace) -> int:
    """Serve the fleet until SIGTERM or SIGINT; 1 when it cannot start or stop cleanly."""
    collect_in_large_batches()
    shape_heap()
    trim_heap_every()
    try:
        config = load_config(args.config_file, overrides(args, ALL_OPTIONS))
    except ConfigError as error:
        raise ConfigError(naming_the_flag(str(error), args, ALL_OPTIONS)) from None
    configure_logging(config.log_level, config.log_format)
    from overseer.app import (
        Exporter,  # the exporter (and its middleware) loads for a valid configuration only
    )
    from overseer.fleet.workers.pool import WorkerStartError

    try:
        exporter = Exporter(config)
    except OSError as error:
        print(
            f"overseer run: cannot listen on {config.web.listen_address}: {error.strerror}", file=sys.stderr
        )
        return 1
    signals = StopSignals(exporter.reload)  # before its parts start: a stop meanwhile waits for them
    try:
        exporter.start()
    except WorkerStartError as error:
        print(f"overseer run: {error}", file=sys.stderr)
        return 1
    signals.wait()
    if not exporter.stop():
        return 1
    log.info("stopped")
    return 0


COMMAND = Command(
    "run",
    "run the exporter",
    "Serve the fleet's diagnostics: /metrics, the JSON API, the status page. Every key of the "
    "configuration file has a flag below, which overrides it (docs/configuration.md).",
    add_arguments,
    run,
)
