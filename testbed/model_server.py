"""The exporter's HTTP endpoint over a fleet model fed by hand, in this process."""

from __future__ import annotations

import re
import threading
from collections.abc import Iterator
from contextlib import contextmanager

from overseer.fleet.exposition import FleetExposition
from overseer.fleet.interface import Fleet
from overseer.fleet.local import LocalFleet
from overseer.model import FleetModel
from overseer.serve.assembler import ExpositionAssembler
from overseer.serve.http import OverseerServer
from overseer.serve.render_timing import RenderTiming


@contextmanager
def serving(model: FleetModel, value_keys: str = ".*") -> Iterator[OverseerServer]:
    """An `OverseerServer` on a free loopback port serving `model` (no transports), until the block ends."""
    fleet = LocalFleet(model, [], FleetExposition(model, re.compile(value_keys)))
    with serving_fleet(fleet, ExpositionAssembler(["dds"])) as server:
        yield server


@contextmanager
def serving_fleet(
    fleet: Fleet, assembler: ExpositionAssembler, render_timing: RenderTiming | None = None
) -> Iterator[OverseerServer]:
    """An `OverseerServer` on a free loopback port serving `fleet`, until the block ends."""
    server = OverseerServer(("127.0.0.1", 0), fleet, assembler, render_timing=render_timing)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield server
    finally:
        server.shutdown()
        server.server_close()
