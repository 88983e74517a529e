"""The inventory file as the fleet follows it: read at start, read again on request, each reload told.

As Prometheus does with its configuration: a file that cannot be read at start stops the exporter with
a configuration error; one that cannot be read later is refused, the inventory before it stays, and
`overseer_inventory_last_reload_successful` says so until a good file is read.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

from overseer.inventory.file import InventoryError, load_inventory
from overseer.model import Inventory

log = logging.getLogger(__name__)


class InventoryReloader:
    """The inventory in force, and the outcome of the last attempt to read it again."""

    def __init__(self, path: str | None, clock: Callable[[], float] = time.time) -> None:
        """Read the file at `path` (None: no inventory); `InventoryError` when it cannot be used."""
        self.path = path
        self._clock = clock
        self._lock = threading.Lock()
        self._apply: Callable[[Inventory], None] | None = None
        self.inventory = Inventory() if path is None else load_inventory(path)
        self.last_successful = True
        self.last_success_at = clock()
        self.problem: str | None = None
        if path is not None:
            log.info("inventory %s: %d robots", path, len(self.inventory.robots))

    def follow_with(self, apply: Callable[[Inventory], None]) -> None:
        """Hand every inventory read from now on to `apply` (the fleet's `set_inventory`)."""
        self._apply = apply

    def reload(self) -> str | None:
        """Read the file again and hand it on; None when it was, else why not (the old one stays)."""
        if self.path is None:
            return "no inventory file is configured (inventory.file)"
        with self._lock:
            started = time.monotonic()
            try:
                inventory = load_inventory(self.path)
            except InventoryError as error:
                self.last_successful = False
                self.problem = str(error)
                log.error("inventory not reloaded, the one before stays: %s", error)
                return self.problem
            if self._apply is not None:
                self._apply(inventory)
            self.inventory = inventory
            self.last_successful = True
            self.last_success_at = self._clock()
            self.problem = None
            log.info(
                "inventory %s reloaded: %d robots in %.3f s",
                self.path,
                len(inventory.robots),
                time.monotonic() - started,
            )
        return None
