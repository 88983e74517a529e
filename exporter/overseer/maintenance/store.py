"""One-off maintenance windows on disk, in the exporter's SQLite database, so they survive restarts.

The windows live in the event history's file (`events.path`) in tables of their own, beside the events,
whether the history is enabled or not; the file is made when the first window is, not before. So is
what the outputs made of each window elsewhere (an Alertmanager silence's id, an Icinga 2 downtime's
name), so that a restarted exporter finds and ends them.
"""

from __future__ import annotations

import sqlite3
import threading
from pathlib import Path

from overseer.database import claim
from overseer.model.maintenance import RobotSelector, Window

_SCHEMA = """
CREATE TABLE IF NOT EXISTS maintenance_windows (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    robots TEXT NOT NULL,
    starts_at REAL NOT NULL,
    ends_at REAL NOT NULL,
    comment TEXT NOT NULL,
    author TEXT NOT NULL,
    created_at REAL NOT NULL,
    ended_at REAL
);
CREATE TABLE IF NOT EXISTS maintenance_effects (
    window TEXT NOT NULL,      -- a window's key
    target TEXT NOT NULL,      -- alertmanager, icinga2
    subject TEXT NOT NULL,     -- what it covers there ('' for the whole window, or an Icinga host)
    reference TEXT NOT NULL,   -- the silence's id, the downtime's name
    PRIMARY KEY (window, target, subject)
);
"""


class StoreUnavailable(RuntimeError):
    """The database cannot be used; the message says why."""


class WindowStore:
    """The one-off windows and their effects, read and written under one lock."""

    def __init__(self, path: str) -> None:
        """Use the SQLite file at `path` (made with the first window); `StoreUnavailable` if it cannot be."""
        self.path = path
        self._lock = threading.Lock()
        self._connection: sqlite3.Connection | None = None
        self._closed = False
        directory = Path(path).parent
        if not directory.is_dir():
            raise StoreUnavailable(
                f"cannot keep maintenance windows in {path!r}: directory {str(directory)!r} does not exist"
            )
        if Path(path).exists():
            self._connect()

    def add(
        self, robots: RobotSelector, start: float, end: float, comment: str, author: str, now: float
    ) -> Window:
        """Store a new window; it comes back with its key."""
        with self._lock:
            cursor = self._connect().execute(
                "INSERT INTO maintenance_windows (robots, starts_at, ends_at, comment, author, created_at) "
                "VALUES (?, ?, ?, ?, ?, ?)",
                (robots.text, start, end, comment, author, now),
            )
        return Window(f"w{cursor.lastrowid}", robots, start, end, comment, author)

    def end_early(self, key: str, at: float) -> None:
        """Record that window `key` ended at `at`."""
        with self._lock:
            self._connect().execute(
                "UPDATE maintenance_windows SET ended_at = ? WHERE id = ?", (at, int(key.removeprefix("w")))
            )

    def windows(self, ending_after: float) -> list[Window]:
        """The one-off windows that end (or ended) after `ending_after`, oldest first."""
        with self._lock:
            if self._connection is None:
                self._refuse_when_closed()
                return []  # no window was ever made here
            rows = self._connection.execute(
                "SELECT id, robots, starts_at, ends_at, comment, author, ended_at FROM maintenance_windows "
                "WHERE MIN(ends_at, COALESCE(ended_at, ends_at)) > ? ORDER BY id",
                (ending_after,),
            ).fetchall()
        return [
            Window(f"w{row[0]}", RobotSelector(row[1]), row[2], row[3], row[4], row[5], ended_early=row[6])
            for row in rows
        ]

    def effects(self, target: str) -> dict[tuple[str, str], str]:
        """(window key, subject) → reference of every effect kept for `target`."""
        with self._lock:
            if self._connection is None:
                self._refuse_when_closed()
                return {}
            rows = self._connection.execute(
                "SELECT window, subject, reference FROM maintenance_effects WHERE target = ?", (target,)
            ).fetchall()
        return {(row[0], row[1]): row[2] for row in rows}

    def keep_effect(self, window: str, target: str, subject: str, reference: str) -> None:
        """Remember what `target` made of a window (for `subject`)."""
        with self._lock:
            self._connect().execute(
                "INSERT OR REPLACE INTO maintenance_effects VALUES (?, ?, ?, ?)",
                (window, target, subject, reference),
            )

    def forget_effect(self, window: str, target: str, subject: str) -> None:
        """The effect is gone (ended, expired): forget it."""
        with self._lock:
            if self._connection is not None:
                self._connection.execute(
                    "DELETE FROM maintenance_effects WHERE window = ? AND target = ? AND subject = ?",
                    (window, target, subject),
                )

    def close(self) -> None:
        """Close the database for good: the last connection to close removes its write-ahead log."""
        with self._lock:
            self._closed = True
            if self._connection is not None:
                self._connection.close()
                self._connection = None

    def _refuse_when_closed(self) -> None:
        """After `close`, saying "no window" would be a lie (maintenance-gated alerts would fire)."""
        if self._closed:
            raise StoreUnavailable(
                f"the maintenance windows in {self.path!r} are closed (the exporter is stopping)"
            )

    def _connect(self) -> sqlite3.Connection:
        """The connection; the file and its tables are made on first use (or `StoreUnavailable`)."""
        if self._connection is not None:
            return self._connection
        self._refuse_when_closed()
        try:
            connection = sqlite3.connect(
                self.path, timeout=5.0, isolation_level=None, check_same_thread=False
            )
            try:
                claim(connection)
                connection.execute("PRAGMA journal_mode = WAL")
                connection.executescript(_SCHEMA)
            except BaseException:
                connection.close()
                raise
        except (OSError, sqlite3.Error) as error:
            raise StoreUnavailable(f"cannot keep maintenance windows in {self.path!r}: {error}") from None
        self._connection = connection
        return connection
