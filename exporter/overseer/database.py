"""The exporter's SQLite file, shared by the event history, the maintenance windows and the robots heard."""

from __future__ import annotations

import sqlite3
from collections.abc import Iterable

APPLICATION_ID = 0x4F565352  # "OVSR": marks the file as Overseer's event database


def claim(connection: sqlite3.Connection, new_file_pragmas: Iterable[str] = ()) -> None:
    """Check the file is an Overseer event database or empty (DatabaseError if not); mark an empty one."""
    tables = {row[0] for row in connection.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
    if tables and connection.execute("PRAGMA application_id").fetchone()[0] != APPLICATION_ID:
        raise sqlite3.DatabaseError("it is an SQLite database, but not an Overseer event database")
    if not tables:
        for pragma in new_file_pragmas:  # some only take effect before a table exists
            connection.execute(f"PRAGMA {pragma}")
        connection.execute(f"PRAGMA application_id = {APPLICATION_ID}")
