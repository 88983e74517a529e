"""The `inventory:` section: the file of the robots the fleet should have (read by `overseer.inventory`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from overseer.config.options import Option, option
from overseer.config.parsers import string

OPTIONS: tuple[Option, ...] = (
    option(
        "inventory.file",
        "none: robots by discovery only",
        "a YAML file of the robots the fleet should have, their labels and the components each must report "
        "(docs/inventory.md); read again on SIGHUP and POST /-/reload",
        metavar="PATH",
    ),
)
KEYS = {entry.key.partition(".")[2] for entry in OPTIONS}


@dataclass(frozen=True)
class InventoryConfig:
    """Where the inventory file is (None: there is none)."""

    file: str | None = None


def inventory_config(raw: dict[str, Any]) -> InventoryConfig:
    """The section from its mapping."""
    path = raw.get("file")
    return InventoryConfig(None if path is None else string(path, "inventory.file"))
