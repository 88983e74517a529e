"""The check's reading of the exporter's JSON API: one robot's document into the verdict's `ReportedRobot`.

Every field is checked: a missing or mistyped one is a `CheckError`, which the check reports as UNKNOWN
naming the field. Only the standard library's cheapest modules are used here (the check's start-up).
"""

from __future__ import annotations

from overseer.verdict import Maintenance, ReportedComponent, ReportedRobot


class CheckError(Exception):
    """A failure that ends the check in UNKNOWN; its text is the status line's."""


def robot_from_document(document: object) -> ReportedRobot:
    """The robot in a `GET /api/v1/robots/<robot>` answer; CheckError naming what is wrong with it."""
    if not isinstance(document, dict):
        raise CheckError("the answer is not a JSON object")
    last_message = document.get("last_message")
    return ReportedRobot(
        name=text_field(document, "robot"),
        up=flag_field(document, "up"),
        last_message=None if last_message is None else number_field(document, "last_message"),
        generated_at=number_field(document, "generated_at"),
        components=[component_from_document(item) for item in list_field(document, "components")],
        # Absent from exporters before Zenoh liveliness: their robots' publishers count as alive.
        publisher_alive="publisher_alive" not in document or flag_field(document, "publisher_alive"),
        # Absent from exporters before maintenance windows, null for a robot in none.
        maintenance=maintenance_from_document(document.get("maintenance")),
        # Absent from exporters before the inventory.
        listed="listed" in document and flag_field(document, "listed"),
    )


def maintenance_from_document(document: object) -> Maintenance | None:
    """The answer's `maintenance` (null or absent: none); CheckError when its fields are wrong."""
    if document is None:
        return None
    if not isinstance(document, dict):
        raise CheckError("'maintenance' is not a JSON object or null")
    until = number_field(document, "until")
    if not 0 <= until < 1e11:
        raise CheckError(f"'until' of 'maintenance' is not a time: {until!r}")
    return Maintenance(
        window=text_field(document, "window"),
        until=until,
        author=text_field(document, "author"),
        comment=text_field(document, "comment"),
    )


def component_from_document(document: object) -> ReportedComponent:
    """One entry of the answer's `components`; CheckError when its fields are missing or mistyped."""
    if not isinstance(document, dict):
        raise CheckError("a component is not a JSON object")
    level = document.get("level")
    if level not in (0, 1, 2, 3) or not isinstance(level, int) or isinstance(level, bool):
        raise CheckError(f"component level {level!r} is not 0, 1, 2 or 3")
    return ReportedComponent(
        name=text_field(document, "name"),
        hardware_id=text_field(document, "hardware_id"),
        level=level,
        message=text_field(document, "message"),
        values=[key_value(item) for item in list_field(document, "values")],
    )


def key_value(document: object) -> tuple[str, str]:
    """One `{"key": ..., "value": ...}` entry of a component's values."""
    if not isinstance(document, dict):
        raise CheckError("a key-value is not a JSON object")
    return text_field(document, "key"), text_field(document, "value")


def text_field(document: dict[str, object], key: str) -> str:
    """`document[key]` when it is a JSON string; CheckError otherwise."""
    value = document.get(key)
    if not isinstance(value, str):
        raise CheckError(f"{key!r} is missing or not a JSON string")
    return value


def flag_field(document: dict[str, object], key: str) -> bool:
    """`document[key]` when it is a JSON boolean; CheckError otherwise."""
    value = document.get(key)
    if not isinstance(value, bool):
        raise CheckError(f"{key!r} is missing or not a JSON boolean")
    return value


def list_field(document: dict[str, object], key: str) -> list[object]:
    """`document[key]` when it is a JSON array; CheckError otherwise."""
    value = document.get(key)
    if not isinstance(value, list):
        raise CheckError(f"{key!r} is missing or not a JSON array")
    return value


def number_field(document: dict[str, object], key: str) -> float:
    """`document[key]` when it is a JSON number; CheckError otherwise."""
    value = document.get(key)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise CheckError(f"{key!r} is missing or not a JSON number")
    return value
