"""The robots heard, on disk in the exporter's SQLite database, so that a restarted exporter remembers them.

They live in the event history's file (`events.path`), in a table of their own, whether the history is
enabled or not, as maintenance windows do. The table holds what the fleet last said it heard: each
robot, its transport, when it was last heard and whether it was down then, and (written at a clean stop)
its components; it is written whole, so a robot the fleet forgot is no longer in it.
"""

from __future__ import annotations

import json
import logging
import sqlite3
import threading
from collections.abc import Iterable
from pathlib import Path

from overseer.database import claim
from overseer.model import RememberedRobot
from overseer.model.state import RememberedComponent

log = logging.getLogger(__name__)


_SCHEMA = """
CREATE TABLE IF NOT EXISTS robots_heard (
    robot TEXT PRIMARY KEY,
    transport TEXT NOT NULL,
    heard_at REAL NOT NULL,    -- unix time of its last message
    down INTEGER NOT NULL,     -- 1 when it was down then
    components TEXT NOT NULL   -- JSON [[name, hardware_id, level, message], ...], at a clean stop
) WITHOUT ROWID;
"""


class RobotRegistry:
    """The table of robots heard, read at start and replaced as the fleet hears on."""

    def __init__(self, path: str) -> None:
        """Use the SQLite file at `path`; without its directory nothing is remembered, and it says so."""
        self.path = path
        self._lock = threading.Lock()
        self._connection: sqlite3.Connection | None = None
        self._closed = False
        self.problem: str | None = None
        directory = Path(path).parent
        if not directory.is_dir():
            self.problem = f"directory {str(directory)!r} does not exist"
            log.error("cannot remember robots across restarts in %r: %s", path, self.problem)

    def load(self) -> list[RememberedRobot]:
        """Every robot remembered, or none when the database cannot be read (logged)."""
        with self._lock:
            connection = self._connect() if Path(self.path).exists() else None
            if connection is None:
                return []
            try:
                rows = connection.execute(
                    "SELECT robot, transport, heard_at, down, components FROM robots_heard"
                ).fetchall()
            except sqlite3.Error as error:
                self._failed("read", error)
                return []
        return [
            RememberedRobot(str(name), str(transport), float(at), bool(down), _components(components))
            for name, transport, at, down, components in rows
        ]

    def save(self, robots: Iterable[RememberedRobot]) -> bool:
        """Make the table hold exactly `robots`; False when it cannot be written (logged)."""
        rows = [
            (
                robot.name,
                robot.transport,
                robot.heard_at,
                int(robot.down),
                json.dumps(robot.components, ensure_ascii=False, separators=(",", ":")),
            )
            for robot in robots
        ]
        with self._lock:
            if not rows and not Path(self.path).exists():
                return True  # nothing to remember: the file is made with the first robot, not before
            connection = self._connect()
            if connection is None:
                return False
            try:
                with connection:
                    connection.execute("DELETE FROM robots_heard")
                    connection.executemany("INSERT INTO robots_heard VALUES (?, ?, ?, ?, ?)", rows)
            except sqlite3.Error as error:
                self._failed("write", error)
                return False
        return True

    def forget(self, robot: str) -> None:
        """Remove one robot at once (retired: a restart before the next save must not bring it back)."""
        with self._lock:
            connection = self._connect() if Path(self.path).exists() else None
            if connection is None:
                return
            try:
                with connection:
                    connection.execute("DELETE FROM robots_heard WHERE robot = ?", (robot,))
            except sqlite3.Error as error:
                self._failed("write", error)

    def close(self) -> None:
        """Close the database for good: a save still running then must not open it again."""
        with self._lock:
            self._closed = True
            if self._connection is not None:
                self._connection.close()
                self._connection = None

    def _connect(self) -> sqlite3.Connection | None:
        if self._connection is None and self.problem is None and not self._closed:
            try:
                connection = sqlite3.connect(self.path, timeout=10, check_same_thread=False)
                try:
                    claim(connection)
                    connection.execute("PRAGMA journal_mode = WAL")
                    connection.executescript(_SCHEMA)
                except BaseException:
                    connection.close()
                    raise
            except sqlite3.Error as error:
                self.problem = str(error)
                self._failed("open", error)
                return None
            self._connection = connection
        return self._connection

    def _failed(self, what: str, error: sqlite3.Error) -> None:
        log.error("cannot %s the robots heard in %r: %s", what, self.path, error)


def _components(text: object) -> tuple[RememberedComponent, ...]:
    """The components kept in one row (none when the text is not what `save` writes)."""
    try:
        items = json.loads(str(text))
    except (ValueError, RecursionError):
        return ()
    if not isinstance(items, list):
        return ()
    return tuple(
        (item[0], item[1], item[2], item[3])
        for item in items
        if isinstance(item, list)
        and len(item) == 4
        and isinstance(item[0], str)
        and isinstance(item[1], str)
        and type(item[2]) is int
        and isinstance(item[3], str)
    )
