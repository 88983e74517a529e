"""The event history on disk: an SQLite database in WAL mode, written in batches by a thread of its own.

Producers (`add`) only pack their batch and append it to an in-memory queue under a lock; the writer
thread takes everything queued every `FLUSH_INTERVAL_SECONDS` and inserts it in one transaction, so a
busy fleet costs one commit a flush, not one a transition. It inserts thousands of rows a statement, not
one: Python's sqlite3 lets go of the interpreter lock for every statement it runs, and a thread that lets
go of it waits for it back as long as another thread keeps it busy (up to 5 ms, the switch interval), so
an `executemany` of one row a statement wrote under 1,000 events a second while the ingest ran flat out,
as it does when a whole fleet is first heard. A full queue drops events and counts them. Events older
than the retention are deleted every `PRUNE_INTERVAL_SECONDS`, and the oldest go whenever the database
outgrows its size cap (the file shrinks too: the database uses incremental auto-vacuum).

Each `add` waits as one block of bytes (`PackedRows`), not as the Python objects of its rows. A fleet's
first look queues hundreds of thousands of events, one a component, while the writer falls behind. As
strings and floats of their own they filled Python's arenas of small objects, which go back to the
system only once empty, and a few objects born meanwhile and living on (the robots remembered, the
relay's routes) kept 60 MB of them at 10,000 robots, for good. Once such a backlog is written, the
heap its blocks took is handed back to the system (`heap_trim.py`).

A database that cannot be opened (a directory that does not exist or is not writable, a file that is
not an Overseer event database or is corrupt) is not fatal: the store says why in one log line, reports
itself down in `overseer_events_store_up`, and counts every event it cannot keep. The exporter goes on
serving metrics. A write that fails later (a full disk) drops that batch, counted, and the next is tried.
"""

from __future__ import annotations

import contextlib
import functools
import itertools
import logging
import math
import os
import sqlite3
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from overseer.database import claim
from overseer.heap_trim import TRIM_AFTER_BACKLOG, trim_heap
from overseer.history.query import EventQuery, encode_cursor
from overseer.model.events import (
    ROW_FIELDS,
    Event,
    EventRow,
    PackedRows,
    event_of_row,
    event_rows,
    pack_rows,
    unpack_rows,
)

log = logging.getLogger(__name__)
event_log = logging.getLogger("overseer.events")

FLUSH_INTERVAL_SECONDS = 0.25
PRUNE_INTERVAL_SECONDS = 60.0
DEFAULT_QUEUE_LIMIT = 200_000
DROP_REASONS = ("queue_full", "write_error", "store_unavailable")

SIZE_CAP_TARGET = 0.9  # pruning for size leaves the database at this share of the cap

_SCHEMA = """
CREATE TABLE IF NOT EXISTS events (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    time REAL NOT NULL,
    robot TEXT NOT NULL,
    kind TEXT NOT NULL,
    component TEXT,
    hardware_id TEXT,
    old_level INTEGER,
    new_level INTEGER,
    message TEXT NOT NULL,
    key_values TEXT NOT NULL
);
CREATE INDEX IF NOT EXISTS events_by_time ON events (time);  -- every index ends in the rowid (id)
CREATE INDEX IF NOT EXISTS events_by_robot ON events (robot, time);
"""
_COLUMNS = "id, time, robot, kind, component, hardware_id, old_level, new_level, message, key_values"
_INSERT = (
    "INSERT INTO events (time, robot, kind, component, hardware_id, old_level, new_level, message,"
    " key_values) VALUES "
)
_ROW = "(" + ", ".join(["?"] * ROW_FIELDS) + ")"
MAX_ROWS_PER_STATEMENT = 2_000


class EventsUnavailable(RuntimeError):
    """The event database could not be opened; the message says why."""


@dataclass(frozen=True)
class StoreSettings:
    """Where the database is and how much of it to keep."""

    path: str
    retention: float  # seconds
    max_size: int  # bytes
    log_events: bool = False  # also log each event (for JSON logs)
    queue_limit: int = DEFAULT_QUEUE_LIMIT


@dataclass(frozen=True)
class StoreStats:
    """What the store did: events written, dropped by reason, the database's size, whether it writes."""

    written: int
    dropped: dict[str, int]
    size_bytes: int
    up: bool


class EventStore:
    """The event database: `add` from any thread, `query` from any thread, one writer thread."""

    def __init__(self, settings: StoreSettings, clock: Callable[[], float] = time.time) -> None:
        """Open (or create) the database at `settings.path`; on failure the store runs degraded."""
        self.settings = settings
        self._clock = clock
        self._queued_blocks: list[bytes] = []  # each `add`'s rows, packed
        self._queued = 0  # rows
        self._behind = False  # a flush took a backlog of `TRIM_AFTER_BACKLOG` or more, not yet drained
        self._queue_lock = threading.Lock()
        self._write_lock = threading.Lock()
        self._read_lock = threading.Lock()
        self._written = 0
        self._dropped: Counter[str] = Counter()
        self._writing_ok = True
        self._last_prune = -math.inf
        self._last_write_error = -math.inf
        self._stopping = threading.Event()
        self._wake = threading.Event()
        self._thread: threading.Thread | None = None
        self._writer: sqlite3.Connection | None = None
        self._reader: sqlite3.Connection | None = None
        self._rows_per_statement = MAX_ROWS_PER_STATEMENT
        self.problem: str | None = None
        try:
            self._writer = _open_database(settings.path)
            self._rows_per_statement = _statement_rows(self._writer)
            self._reader = _connect(settings.path)
        except (sqlite3.Error, OSError) as error:
            self.problem = _describe_open_error(settings.path, error)
            if self._writer is not None:
                self._writer.close()
                self._writer = None
            log.error("%s; events are not being written (the exporter goes on serving metrics)", self.problem)

    @property
    def available(self) -> bool:
        """True when the database is open."""
        return self._writer is not None

    def add(self, events: list[Event]) -> None:
        """Queue events for the writer; drops (and counts) what does not fit in the queue."""
        if events:
            self.add_rows(event_rows(events))

    def add_rows(self, rows: list[EventRow]) -> None:
        """Queue events as rows (`event_rows`) for the writer; drops (and counts) what does not fit."""
        if rows:
            self.add_packed(pack_rows(rows))

    def add_packed(self, packed: PackedRows) -> None:
        """Queue packed rows (`pack_rows`) for the writer; drops (and counts) what does not fit."""
        if not packed.events:
            return
        if self._writer is None:
            with self._queue_lock:
                self._dropped["store_unavailable"] += packed.events
            self._log(_unpacked([packed.block]), None)  # a log shipper still gets them
            return
        with self._queue_lock:
            room = self.settings.queue_limit - self._queued
            if room < packed.events:
                self._dropped["queue_full"] += packed.events - max(room, 0)
                if room <= 0:
                    return
                packed = pack_rows(unpack_rows(packed.block)[:room])
            self._queued_blocks.append(packed.block)
            self._queued += packed.events

    def start(self) -> None:
        """Start the writer thread (nothing to do when the database could not be opened)."""
        if self._writer is None or self._thread is not None:
            return
        self.prune()
        self._thread = threading.Thread(target=self._run, name="event-writer", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Write what is queued, stop the writer and close the database."""
        self._stopping.set()
        self._wake.set()
        if self._thread is not None:
            self._thread.join(timeout=30)
        self.flush()
        with self._write_lock:
            if self._writer is not None:
                with contextlib.suppress(sqlite3.Error):  # a busy reader: SQLite checkpoints at close anyway
                    self._writer.execute("PRAGMA wal_checkpoint(TRUNCATE)")
                self._writer.close()
                self._writer = None
        with self._read_lock:
            if self._reader is not None:
                self._reader.close()
                self._reader = None

    def flush(self) -> int:
        """Write everything queued now, in the calling thread; returns how many events were written."""
        with self._queue_lock:
            blocks, count, self._queued_blocks, self._queued = self._queued_blocks, self._queued, [], 0
        self._trim_once_drained(count)
        if not blocks:
            return 0
        with self._write_lock:
            return self._write(blocks, count)

    def _trim_once_drained(self, taken: int) -> None:
        """Hand the heap back at the first flush that takes little after one that took a backlog."""
        if taken >= TRIM_AFTER_BACKLOG:
            self._behind = True
        elif self._behind:
            self._behind = False
            trim_heap()  # what the backlog's blocks took, written by the flushes before this one

    def prune(self) -> int:
        """Delete events older than the retention, and the oldest beyond the size cap; returns how many."""
        with self._write_lock:
            writer = self._writer
            if writer is None:
                return 0
            self._last_prune = time.monotonic()
            try:
                horizon = self._clock() - self.settings.retention
                deleted = writer.execute("DELETE FROM events WHERE time < ?", (horizon,)).rowcount
                deleted += self._prune_to_size(writer)
                if deleted:
                    writer.execute("PRAGMA incremental_vacuum")
                return deleted
            except sqlite3.Error as error:
                log.error("cannot prune the event database %r: %s", self.settings.path, error)
                return 0

    def query(self, query: EventQuery) -> tuple[list[dict[str, Any]], str | None]:
        """The events matching `query`, newest first, and the cursor of the next page (or None)."""
        clauses: list[str] = []
        parameters: list[Any] = []
        if query.robot is not None:
            clauses.append("robot = ?")
            parameters.append(query.robot)
        if query.component is not None:
            clauses.append("instr(component, ?) > 0")
            parameters.append(query.component)
        if query.levels:
            clauses.append(f"new_level IN ({', '.join('?' * len(query.levels))})")
            parameters.extend(int(level) for level in query.levels)
        if query.since is not None:
            clauses.append("time >= ?")
            parameters.append(query.since)
        if query.until is not None:
            clauses.append("time <= ?")
            parameters.append(query.until)
        if query.before is not None:
            clauses.append("(time < ? OR (time = ? AND id < ?))")
            parameters.extend([query.before[0], query.before[0], query.before[1]])
        where = f" WHERE {' AND '.join(clauses)}" if clauses else ""
        sql = f"SELECT {_COLUMNS} FROM events{where} ORDER BY time DESC, id DESC LIMIT ?"
        parameters.append(query.limit + 1)
        with self._read_lock:
            if self._reader is None:
                raise EventsUnavailable(self.problem or "the event database is closed")
            rows = self._reader.execute(sql, parameters).fetchall()
        documents = [_document(row) for row in rows[: query.limit]]
        more = len(rows) > query.limit
        cursor = encode_cursor(documents[-1]["time"], documents[-1]["id"]) if more else None
        return documents, cursor

    def stats(self) -> StoreStats:
        """Counts and the database's size now (the main file and its write-ahead log)."""
        size = 0
        for suffix in ("", "-wal"):
            with contextlib.suppress(OSError):  # not there (yet)
                size += os.stat(self.settings.path + suffix).st_size
        with self._queue_lock:
            dropped = {reason: self._dropped.get(reason, 0) for reason in DROP_REASONS}
            written = self._written
        return StoreStats(written, dropped, size, self._writer is not None and self._writing_ok)

    def _run(self) -> None:
        while not self._stopping.is_set():
            self._wake.wait(FLUSH_INTERVAL_SECONDS)
            self.flush()
            if time.monotonic() - self._last_prune >= PRUNE_INTERVAL_SECONDS:
                self.prune()

    def _write(self, blocks: list[bytes], count: int) -> int:
        """Insert the `count` rows packed in `blocks`, in order; how many were written."""
        writer = self._writer
        if writer is None:
            with self._queue_lock:
                self._dropped["store_unavailable"] += count
            return 0
        try:
            writer.execute("BEGIN IMMEDIATE")  # the write lock first: the ids read next stay ours
            first = _sequence(writer) if self.settings.log_events else 0
            self._insert(writer, blocks)
            writer.execute("COMMIT")
        except (sqlite3.Error, ValueError, EOFError, TypeError) as error:  # the last three: a block unpacked
            if writer.in_transaction:
                writer.execute("ROLLBACK")
            with self._queue_lock:
                self._dropped["write_error"] += count
            self._writing_ok = False
            if time.monotonic() - self._last_write_error > 60:  # one line a minute while it lasts
                log.error(
                    "cannot write to the event database %r: %s; %d events dropped (counted in "
                    "overseer_events_dropped_total)",
                    self.settings.path,
                    error,
                    count,
                )
            self._last_write_error = time.monotonic()
            if isinstance(error, sqlite3.Error):  # the blocks read: a log shipper still gets them
                self._log(_unpacked(blocks), None)
            return 0
        self._writing_ok = True
        with self._queue_lock:
            self._written += count
        self._log(_unpacked(blocks), first)
        if self._used_bytes(writer) > self.settings.max_size:
            deleted = self._prune_to_size(writer)
            if deleted:
                writer.execute("PRAGMA incremental_vacuum")
        return count

    def _insert(self, writer: sqlite3.Connection, blocks: list[bytes]) -> None:
        """INSERT the rows packed in `blocks`, a block at a time: full INSERTs, then `_rest_sizes`."""
        per_statement = self._rows_per_statement
        full = per_statement * ROW_FIELDS
        fields: list[Any] = []
        for block in blocks:
            fields.extend(itertools.chain.from_iterable(unpack_rows(block)))
            start = 0
            while len(fields) - start >= full:
                writer.execute(insert_statement(per_statement), fields[start : start + full])
                start += full
            del fields[:start]
        start = 0
        for size in _rest_sizes(len(fields) // ROW_FIELDS):
            end = start + size * ROW_FIELDS
            writer.execute(insert_statement(size), fields[start:end])
            start = end

    def _log(self, rows: Iterable[EventRow], last_id_before: int | None) -> None:
        """Log each event as one line when asked to (JSON logs); with ids when they were stored."""
        if not self.settings.log_events:
            return
        for offset, row in enumerate(rows, start=1):
            event_id = None if last_id_before is None else last_id_before + offset
            event_log.info("event", extra={"event": event_of_row(row).document(event_id)})

    def _used_bytes(self, writer: sqlite3.Connection) -> int:
        pages = writer.execute("PRAGMA page_count").fetchone()[0]
        free = writer.execute("PRAGMA freelist_count").fetchone()[0]
        page_size = writer.execute("PRAGMA page_size").fetchone()[0]
        return int((pages - free) * page_size)

    def _prune_to_size(self, writer: sqlite3.Connection) -> int:
        """Delete the oldest events until the database is within `SIZE_CAP_TARGET` of its cap."""
        used = self._used_bytes(writer)
        if used <= self.settings.max_size:
            return 0
        count = writer.execute("SELECT count(*) FROM events").fetchone()[0]
        share = 1.0 - SIZE_CAP_TARGET * self.settings.max_size / used
        doomed = min(count, max(1, math.ceil(count * share)))
        deleted: int = writer.execute(
            "DELETE FROM events WHERE id IN (SELECT id FROM events ORDER BY time, id LIMIT ?)", (doomed,)
        ).rowcount
        log.info("event database over its size cap: deleted the %d oldest events", deleted)
        return deleted


def _statement_rows(connection: sqlite3.Connection) -> int:
    """How many events one INSERT writes: `MAX_ROWS_PER_STATEMENT`, fewer where SQLite binds fewer values."""
    bound = connection.getlimit(sqlite3.SQLITE_LIMIT_VARIABLE_NUMBER)
    return max(1, min(MAX_ROWS_PER_STATEMENT, bound // ROW_FIELDS))


def _rest_sizes(rows: int) -> Iterator[int]:
    """How many of a flush's last `rows` events (fewer than a full INSERT's) each INSERT writes: powers of 2.

    sqlite3 keeps each INSERT text it ran prepared (128 texts a connection), about 1.2 kB an event of
    it. With one text for every length a flush's last chunk happened to have, those statements took up
    to 150 MB of the exporter's memory; the rest written as powers of two needs a dozen texts in all.
    """
    size = 1 << max(rows.bit_length() - 1, 0)
    while rows:
        if size <= rows:
            yield size
            rows -= size
        size >>= 1


def _unpacked(blocks: list[bytes]) -> Iterator[EventRow]:
    """The rows packed in `blocks`, in order, unpacked a block at a time."""
    for block in blocks:
        yield from unpack_rows(block)


@functools.lru_cache(maxsize=16)
def insert_statement(rows: int) -> str:
    """The INSERT of `rows` events (one text a size, so sqlite3 reuses its prepared statement)."""
    return _INSERT + ", ".join([_ROW] * rows)


def _sequence(writer: sqlite3.Connection) -> int:
    """The last id AUTOINCREMENT gave out (ids of deleted events are never reused)."""
    row = writer.execute("SELECT seq FROM sqlite_sequence WHERE name = 'events'").fetchone()
    return int(row[0]) if row else 0


def _connect(path: str) -> sqlite3.Connection:
    connection = sqlite3.connect(path, timeout=5.0, isolation_level=None, check_same_thread=False)
    connection.execute("PRAGMA busy_timeout = 5000")
    return connection


def _open_database(path: str) -> sqlite3.Connection:
    """The writer's connection to a new or existing Overseer event database, in WAL mode."""
    directory = Path(path).parent
    if not directory.is_dir():
        raise OSError(f"directory {str(directory)!r} does not exist")
    connection = _connect(path)
    try:
        claim(connection, ["auto_vacuum = INCREMENTAL"])
        mode = connection.execute("PRAGMA journal_mode = WAL").fetchone()[0]
        if str(mode).lower() != "wal":
            raise sqlite3.OperationalError(f"cannot switch to WAL mode (journal mode is {mode})")
        connection.execute("PRAGMA synchronous = NORMAL")
        connection.execute("PRAGMA journal_size_limit = 16777216")
        connection.execute("PRAGMA cache_size = -16000")  # 16 MB: inserts touch a page per robot in the index
        connection.executescript(_SCHEMA)
    except BaseException:
        connection.close()
        raise
    return connection


def _describe_open_error(path: str, error: BaseException) -> str:
    if isinstance(error, sqlite3.DatabaseError) and not isinstance(error, sqlite3.OperationalError):
        return (
            f"cannot use the event database {path!r}: {error} "
            "(move it away or delete it to start a new history)"
        )
    reason = error.strerror if isinstance(error, OSError) and error.strerror else str(error)
    return f"cannot open the event database {path!r}: {reason} (is its directory there and writable?)"


def _document(row: tuple[Any, ...]) -> dict[str, Any]:
    event_id, *stored = row
    return event_of_row(tuple(stored)).document(event_id)
