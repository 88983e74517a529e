"""One transition of the fleet, as it is stored, logged and served by /api/v1/events."""

from __future__ import annotations

import json
import marshal
from collections.abc import Callable
from typing import Any, Literal, NamedTuple, get_args

from overseer.levels import Level

EventKind = Literal[
    "level",
    "robot_down",
    "robot_up",
    "appeared",
    "missing",
    "expired",
    "retired",
    "unlisted",
    "reattributed",
    "maintenance_start",
    "maintenance_end",
]
EVENT_KINDS: tuple[EventKind, ...] = get_args(EventKind)
_LEVEL_NAMES = {level: level.name for level in Level}
_LEVELS = tuple(Level)
_NO_VALUES = "[]"
_quote = json.encoder.encode_basestring_ascii  # json.dumps's own, without its per-call setup (2 µs an event)


class Event(NamedTuple):
    """A transition: a component's level, a robot going down or up, a component appearing, going, expiring.

    `component` and `hardware_id` are None for events of a whole robot; `old_level` is None when nothing
    was known before (a first report), `new_level` None when nothing is known after (missing, expired).
    A named tuple, not a frozen dataclass: a robot's first message makes one a component, and a frozen
    dataclass took 3 µs to build against 0.6 µs.
    """

    time: float
    robot: str
    kind: EventKind
    component: str | None = None
    hardware_id: str | None = None
    old_level: Level | None = None
    new_level: Level | None = None
    message: str = ""
    values: tuple[tuple[str, str], ...] = ()

    def document(self, event_id: int | None) -> dict[str, Any]:
        """The event as the JSON API and the JSON log show it, under `event_id` (None: not stored)."""
        return {
            "id": event_id,
            "time": self.time,
            "robot": self.robot,
            "component": self.component,
            "hardware_id": self.hardware_id,
            "kind": self.kind,
            "old_level": None if self.old_level is None else int(self.old_level),
            "new_level": None if self.new_level is None else int(self.new_level),
            "old_state": None if self.old_level is None else _LEVEL_NAMES[self.old_level],
            "new_state": None if self.new_level is None else _LEVEL_NAMES[self.new_level],
            "message": self.message,
            "values": [{"key": key, "value": value} for key, value in self.values],
        }


# An event as the store keeps it: time, robot, kind, component, hardware_id, old level, new level, message,
# and the key-values as a JSON list of [key, value] pairs. Plain values only, of the built-in types
# themselves (no subclass, no enum: `marshal` packs them, `pack_rows`): a worker sends its events to the
# exporter's store as rows, which cross a pipe for a fraction of what named tuples holding levels cost
# (pickled and read back, 1.5 µs against 8).
EventRow = tuple[float, str, str, str | None, str | None, int | None, int | None, str, str]
ROW_FIELDS = len(get_args(EventRow))


def event_rows(events: list[Event]) -> list[EventRow]:
    """`events` as the store's rows."""
    return [
        (
            time_,
            robot,
            kind,
            component,
            hardware_id,
            None if old_level is None else int(old_level),
            None if new_level is None else int(new_level),
            message,
            _values_json(values) if values else _NO_VALUES,
        )
        for time_, robot, kind, component, hardware_id, old_level, new_level, message, values in events
    ]


def event_of_row(row: EventRow) -> Event:
    """The event a stored row holds."""
    at, robot, kind, component, hardware_id, old_level, new_level, message, values = row
    return Event(
        at,
        robot,
        kind,  # type: ignore[arg-type]  # the store holds only the kinds it was given
        component,
        hardware_id,
        None if old_level is None else _LEVELS[old_level],
        None if new_level is None else _LEVELS[new_level],
        message,
        tuple((key, value) for key, value in json.loads(values)),
    )


def _values_json(values: tuple[tuple[str, str], ...]) -> str:
    """`json.dumps(values)` without spaces: a list of [key, value] pairs."""
    return "[" + ",".join(["[" + _quote(key) + "," + _quote(value) + "]" for key, value in values]) + "]"


# Where transitions go, a batch at a time: the event store, or a worker's pipe to it.
EventSink = Callable[[list[Event]], None]


class PackedRows(NamedTuple):
    """How many event rows, and the rows packed into one block of bytes (`pack_rows`).

    Events wait in this form for the store's writer, and cross from a worker to the exporter in it: a
    fleet's first look gives hundreds of thousands at once, and as strings and floats of their own they
    would fill Python's arenas of small objects, given back only once empty (`history/store.py`).
    """

    events: int
    block: bytes


def pack_rows(rows: list[EventRow]) -> PackedRows:
    """`rows` packed; ValueError for a row of other than `ROW_FIELDS` plain values."""
    if any(len(row) != ROW_FIELDS for row in rows):
        raise ValueError(f"event rows of other than {ROW_FIELDS} fields")
    return PackedRows(len(rows), marshal.dumps(rows))  # ValueError too for what is not a plain value


def unpack_rows(block: bytes) -> list[EventRow]:
    """The rows `pack_rows` packed into `block`."""
    rows: list[EventRow] = marshal.loads(block)
    return rows


# Where a worker's transitions go in the exporter, packed: the event store.
PackedRowSink = Callable[[PackedRows], None]
