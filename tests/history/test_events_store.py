"""The event store on a real SQLite file: batches, paging, filters, pruning, restarts and failures."""

from __future__ import annotations

import contextlib
import gc
import logging
import multiprocessing
import os
import sqlite3
import subprocess
import sys
import time
import tracemalloc
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
from prometheus_client import generate_latest
from prometheus_client.registry import CollectorRegistry

from overseer.config.events import EventsConfig
from overseer.history import store as store_module
from overseer.history.metrics import EventsCollector
from overseer.history.query import EventQuery, decode_cursor
from overseer.history.service import EventHistory
from overseer.history.store import (
    DEFAULT_QUEUE_LIMIT,
    MAX_ROWS_PER_STATEMENT,
    EventStore,
    EventsUnavailable,
    StoreSettings,
)
from overseer.levels import Level
from overseer.model.events import Event, EventRow, event_of_row, event_rows, pack_rows
from support.clock import ManualClock

DAY = 86400.0
HOSTILE = [
    'quote"d',
    "back\\slash",
    "new\nline",
    "unicode ☃ 🤖",
    "<script>alert(1)</script>",
    "nul\x00byte",
    "",
]


def settings(path: Path, retention: float = 30 * DAY, max_size: int = 10**9, **extra: int) -> StoreSettings:
    return StoreSettings(str(path), retention, max_size, **extra)  # type: ignore[arg-type]


def level_event(at: float, robot: str = "robot1", component: str = "/Power/Battery", level: int = 2) -> Event:
    return Event(
        at,
        robot,
        "level",
        component,
        "",
        Level.OK,
        Level(level),
        f"level {level} at {at}",
        (("voltage", "11.2"), ("state", "charging")),
    )


def everything(store: EventStore, query: EventQuery | None = None) -> list[dict[str, object]]:
    """Every matching event, page by page through the cursors."""
    query = query or EventQuery(limit=1000)
    found: list[dict[str, object]] = []
    while True:
        page, cursor = store.query(query)
        found.extend(page)
        if cursor is None:
            return found
        query = EventQuery(
            query.robot,
            query.component,
            query.levels,
            query.since,
            query.until,
            query.limit,
            decode_cursor(cursor),
        )


def metrics(store: EventStore) -> str:
    registry = CollectorRegistry()
    registry.register(EventsCollector(store))
    return generate_latest(registry).decode()


def test_queued_events_are_written_in_batches_by_the_writer_thread(tmp_path: Path) -> None:
    store = EventStore(settings(tmp_path / "events.db"))
    base = 1_700_000_000.0
    for batch in range(50):
        store.add([level_event(base + batch * 100 + i) for i in range(100)])
    assert store.stats().written == 0  # nothing is written by `add` itself
    store.start()
    try:
        deadline = time.monotonic() + 10
        while store.stats().written < 5000 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert store.stats().written == 5000
    finally:
        store.stop()
    connection = sqlite3.connect(tmp_path / "events.db")
    assert connection.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    ids = [row[0] for row in connection.execute("SELECT id FROM events ORDER BY time")]
    assert ids == list(range(1, 5001))


def test_a_batch_is_written_thousands_of_events_a_statement_with_its_ids_and_values_in_order(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    # Each statement lets go of the interpreter lock and waits for it back: one a row wrote under 1,000 a
    # second while another thread kept the interpreter busy (the ingest when a fleet is first heard).
    store = EventStore(settings(tmp_path / "events.db", log_events=True))
    store.add([level_event(0.0)])
    store.flush()  # ids go on from the last one given out
    inserts: list[str] = []
    assert store._writer is not None
    store._writer.set_trace_callback(lambda sql: inserts.append(sql) if sql.startswith("INSERT") else None)
    count = 2 * MAX_ROWS_PER_STATEMENT + 7
    events = [
        Event(
            1000.0 + i / 3,  # not exact in decimal: each time comes back bit for bit
            f"robot{i % 13}",
            "appeared" if i % 2 else "level",
            f"/Sensors/Sensor {i}",
            HOSTILE[i % len(HOSTILE)],
            None if i % 2 else Level.OK,
            Level(i % 4),
            f"message {i}",
            tuple((f"key {k}", f"{HOSTILE[(i + k) % len(HOSTILE)]} {i}") for k in range(i % 4)),
        )
        for i in range(count)
    ]
    for start, end in ((0, 1500), (1500, 3000), (3000, count)):  # statements across the batches' ends
        store.add(events[start:end])
    with caplog.at_level(logging.INFO, logger="overseer.events"):
        assert store.flush() == count
    assert len(inserts) == 5  # two of 2,000 events, then the 7 left as 4, 2 and 1
    stored = list(reversed(everything(store, EventQuery(since=1000.0, limit=5000))))
    assert stored == [event.document(event_id) for event_id, event in enumerate(events, start=2)]
    logged = [r.event for r in caplog.records if r.name == "overseer.events"]  # type: ignore[attr-defined]
    assert logged == stored


def test_flushes_of_every_size_run_a_dozen_insert_texts_so_sqlite_keeps_few_prepared(tmp_path: Path) -> None:
    # sqlite3 keeps each INSERT text it ran prepared, about 1.2 kB an event of it: one text for each
    # length a flush's last chunk had took up to 150 MB of the exporter, whose flushes take what came
    store = EventStore(settings(tmp_path / "events.db"))
    assert store._writer is not None
    sizes: set[int] = set()  # the texts, by the events each inserts (the trace has the values in them)
    store._writer.set_trace_callback(
        lambda sql: sizes.add(sql.count("), (") + 1) if sql.startswith("INSERT") else None
    )
    total = 0
    for count in range(1, MAX_ROWS_PER_STATEMENT + 200, 53):  # 42 flushes, each of a size of its own
        store.add([level_event(float(total + i), component=f"/c{i}") for i in range(count)])
        total += count
        assert store.flush() == count
    assert len(sizes) <= MAX_ROWS_PER_STATEMENT.bit_length() + 1, sorted(sizes)
    assert max(sizes) == MAX_ROWS_PER_STATEMENT
    assert store.stats().written == total
    with contextlib.closing(sqlite3.connect(tmp_path / "events.db")) as reader:
        assert reader.execute("SELECT count(*) FROM events").fetchone() == (total,)


def test_pages_are_newest_first_and_the_cursor_loses_nothing_even_at_equal_times(tmp_path: Path) -> None:
    store = EventStore(settings(tmp_path / "events.db"))
    store.add([level_event(1000.0 + (i // 7), component=f"/c{i}") for i in range(250)])
    store.flush()
    first, cursor = store.query(EventQuery(limit=100))
    assert len(first) == 100 and cursor is not None
    events = everything(store, EventQuery(limit=33))
    assert len(events) == 250 and len({e["id"] for e in events}) == 250
    keys = [(e["time"], e["id"]) for e in events]
    assert keys == sorted(keys, reverse=True)
    assert events[:100] == first
    last_page, cursor = store.query(EventQuery(limit=250))
    assert cursor is None and len(last_page) == 250


def test_filters_robot_exact_component_substring_levels_and_time_range(tmp_path: Path) -> None:
    store = EventStore(settings(tmp_path / "events.db"))
    store.add(
        [
            level_event(100, "robot1", "/Power/Battery", 2),
            level_event(101, "robot1", "/Power/Laptop Battery", 1),
            level_event(102, "robot10", "/Power/Battery", 2),
            level_event(103, "robot1", "/Motor/Motor1", 0),
            Event(104, "robot1", "robot_down", old_level=Level.OK, new_level=Level.STALE, message="gone"),
        ]
    )
    store.flush()

    def times(**filters: object) -> list[object]:
        return [e["time"] for e in store.query(EventQuery(**filters))[0]]  # type: ignore[arg-type]

    assert times(robot="robot1") == [104, 103, 101, 100]
    assert times(component="Battery") == [102, 101, 100]
    assert times(component="battery") == []  # case-sensitive
    assert times(levels=(Level.ERROR, Level.WARN)) == [102, 101, 100]
    assert times(levels=(Level.STALE,)) == [104]
    assert times(since=101, until=103) == [103, 102, 101]
    assert times(robot="robot1", component="Power", levels=(Level.ERROR,)) == [100]


def test_the_document_has_the_contracts_shape(tmp_path: Path) -> None:
    store = EventStore(settings(tmp_path / "events.db"))
    store.add([level_event(1700000000.5), Event(1700000001.0, "robot1", "robot_down", new_level=Level.STALE)])
    store.flush()
    down, level = store.query(EventQuery())[0]
    assert level == {
        "id": 1,
        "time": 1700000000.5,
        "robot": "robot1",
        "component": "/Power/Battery",
        "hardware_id": "",
        "kind": "level",
        "old_level": 0,
        "new_level": 2,
        "old_state": "OK",
        "new_state": "ERROR",
        "message": "level 2 at 1700000000.5",
        "values": [{"key": "voltage", "value": "11.2"}, {"key": "state", "value": "charging"}],
    }
    assert down["component"] is None and down["hardware_id"] is None and down["old_state"] is None


def test_hostile_strings_are_stored_and_returned_intact(tmp_path: Path) -> None:
    store = EventStore(settings(tmp_path / "events.db"))
    store.add(
        [
            Event(1000.0 + i, text or "r", "level", text, text, Level.OK, Level.WARN, text, ((text, text),))
            for i, text in enumerate(HOSTILE)
        ]
    )
    store.flush()
    store.stop()
    reopened = EventStore(settings(tmp_path / "events.db"))
    returned = list(reversed(reopened.query(EventQuery())[0]))
    assert [(e["component"], e["hardware_id"], e["message"]) for e in returned] == [
        (t, t, t) for t in HOSTILE
    ]
    assert [e["values"] for e in returned] == [[{"key": t, "value": t}] for t in HOSTILE]
    assert [e["robot"] for e in returned] == [t or "r" for t in HOSTILE]
    assert [e["robot"] for e in reopened.query(EventQuery(robot='quote"d'))[0]] == ['quote"d']


def test_rows_sent_through_a_pipe_are_stored_as_the_events_they_came_from(tmp_path: Path) -> None:
    # An ingest worker sends its events as packed rows; the exporter's store writes them as it writes events.
    events = [
        Event(1000.0 + i, text or "r", "level", text, text, Level.OK, Level.WARN, text, ((text, text),))
        for i, text in enumerate(HOSTILE)
    ] + [Event(2000.0, "robot1", "robot_down", message="silent"), level_event(2001.0)]
    assert [event_of_row(row) for row in event_rows(events)] == events
    sent, received = multiprocessing.Pipe(duplex=False)
    received.send(pack_rows(event_rows(events)))
    direct = EventStore(settings(tmp_path / "direct.db"))
    piped = EventStore(settings(tmp_path / "piped.db"))
    direct.add(events)
    piped.add_packed(sent.recv())
    assert direct.flush() == piped.flush() == len(events)
    assert direct.query(EventQuery())[0] == piped.query(EventQuery())[0]


def test_events_survive_a_restart_and_ids_keep_growing_after_pruning(tmp_path: Path) -> None:
    clock = ManualClock()
    path = tmp_path / "events.db"
    store = EventStore(settings(path, retention=DAY), clock=clock)
    store.add([level_event(clock.now - 2 * DAY), level_event(clock.now - 1)])
    store.flush()
    store.stop()
    again = EventStore(settings(path, retention=DAY), clock=clock)
    assert [e["id"] for e in again.query(EventQuery())[0]] == [2, 1]
    assert again.prune() == 1
    again.add([level_event(clock.now)])
    again.flush()
    assert [e["id"] for e in again.query(EventQuery())[0]] == [3, 2]
    again.stop()


def test_retention_drops_old_events_at_start_and_on_prune(tmp_path: Path) -> None:
    clock = ManualClock()
    path = tmp_path / "events.db"
    store = EventStore(settings(path, retention=DAY), clock=clock)
    store.add([level_event(clock.now - 3 * DAY + i * DAY) for i in range(4)])
    store.flush()
    assert store.prune() == 2
    assert len(store.query(EventQuery())[0]) == 2
    clock.now += DAY
    store.start()  # the writer prunes as it starts
    try:
        assert [e["time"] for e in store.query(EventQuery())[0]] == [clock.now - DAY]
    finally:
        store.stop()


def test_the_size_cap_deletes_the_oldest_and_shrinks_the_file(tmp_path: Path) -> None:
    path = tmp_path / "events.db"
    cap = 1_000_000
    store = EventStore(settings(path, max_size=cap))
    big = "x" * 2000
    newest = 0.0
    for batch in range(30):  # about 3 MB written into a 1 MB cap
        events = [
            Event(float(batch * 50 + i), "robot1", "level", "/c", "", Level.OK, Level.ERROR, big)
            for i in range(50)
        ]
        newest = events[-1].time
        store.add(events)
        store.flush()
    kept = everything(store)
    assert kept[0]["time"] == newest
    assert 0 < len(kept) < 1500
    times = sorted(float(e["time"]) for e in kept)  # type: ignore[arg-type]
    assert times == [float(t) for t in range(int(times[0]), int(newest) + 1)]  # only the oldest went
    assert os.path.getsize(path) <= cap * 1.1
    store.stop()


def test_a_full_queue_drops_and_counts(tmp_path: Path) -> None:
    store = EventStore(settings(tmp_path / "events.db", queue_limit=100))
    store.add([level_event(float(i)) for i in range(80)])
    store.add([level_event(float(i)) for i in range(50)])
    store.add([level_event(1.0)])
    assert store.flush() == 100
    stats = store.stats()
    assert stats.dropped["queue_full"] == 31 and stats.written == 100
    assert 'overseer_events_dropped_total{reason="queue_full"} 31.0' in metrics(store)


def test_the_heap_is_given_back_once_a_backlog_of_events_is_written(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    trimmed: list[int] = []
    store = EventStore(settings(tmp_path / "events.db"))
    monkeypatch.setattr(store_module, "TRIM_AFTER_BACKLOG", 50)

    def trim() -> bool:
        trimmed.append(store.stats().written)
        return True

    monkeypatch.setattr(store_module, "trim_heap", trim)
    for backlog in (60, 70, 10, 10, 40, 5):  # a backlog written in two flushes, then small flushes only
        store.add([level_event(float(i)) for i in range(backlog)])
        store.flush()
    assert trimmed == [130]  # once, at the first small flush after the backlog, which it had written
    store.stop()


def test_a_packed_batch_beyond_the_queue_keeps_what_fits_in_order(tmp_path: Path) -> None:
    store = EventStore(settings(tmp_path / "events.db", queue_limit=100))
    store.add_packed(pack_rows(event_rows([level_event(float(i)) for i in range(70)])))
    store.add_packed(pack_rows(event_rows([level_event(float(i)) for i in range(70, 140)])))
    store.add_packed(pack_rows(event_rows([level_event(200.0)])))
    assert store.flush() == 100
    assert store.stats().dropped["queue_full"] == 41
    assert [event["time"] for event in everything(store)] == [float(i) for i in reversed(range(100))]


def test_queued_events_keep_no_python_object_of_their_own(tmp_path: Path) -> None:
    # A fleet's first look queues hundreds of thousands of events while the writer falls behind. As
    # strings and floats of their own they filled Python's arenas of small objects, which stay the
    # process's until empty: objects born meanwhile and living on kept 60 MB of them at 10,000 robots.
    store = EventStore(settings(tmp_path / "events.db"))  # not started: what is queued stays queued
    count = 20_000
    gc.collect()
    tracemalloc.start()
    try:
        blocks_before, bytes_before = sys.getallocatedblocks(), tracemalloc.get_traced_memory()[0]
        for start in range(0, count, 1_000):  # in batches, as a worker's events come
            rows: list[EventRow] = [
                (1000.0 + i, f"robot{i}", "level", f"/c{i}", f"hw{i}", 0, 2, f"message {i}", f'[["v","{i}"]]')
                for i in range(start, start + 1_000)
            ]
            store.add_rows(rows)
            del rows
        gc.collect()
        objects = sys.getallocatedblocks() - blocks_before
        kept = tracemalloc.get_traced_memory()[0] - bytes_before
    finally:
        tracemalloc.stop()
    # A block of bytes a batch: no string, float or tuple an event (the fields as objects kept six).
    assert objects / count < 0.01, f"{objects / count:.2f} Python objects an event queued"
    assert kept / count < 150, f"{kept / count:.0f} bytes an event queued"
    assert store.flush() == count
    newest, _ = store.query(EventQuery(limit=2))
    assert [(event["robot"], event["hardware_id"], event["values"]) for event in newest] == [
        ("robot19999", "hw19999", [{"key": "v", "value": "19999"}]),
        ("robot19998", "hw19998", [{"key": "v", "value": "19998"}]),
    ]
    assert len(everything(store)) == count


def test_rows_other_than_plain_values_are_refused_and_the_next_batch_is_kept(tmp_path: Path) -> None:
    store = EventStore(settings(tmp_path / "events.db"))
    [good] = event_rows([level_event(1.0)])
    with pytest.raises(ValueError):
        store.add_rows([good, (*good[:7], object(), good[8])])  # type: ignore[list-item]
    store.add_rows(event_rows([level_event(2.0)]))
    assert store.flush() == 1 and store.stats().dropped["queue_full"] == 0
    [event] = everything(store)
    assert (event["time"], event["new_level"]) == (2.0, 2)


def test_a_row_of_the_wrong_length_is_refused_and_shifts_no_other(tmp_path: Path) -> None:
    store = EventStore(settings(tmp_path / "events.db"))
    good = event_rows([level_event(1.0)])
    with pytest.raises(ValueError, match="9 fields"):
        store.add_rows([*good, good[0][:8]])  # type: ignore[list-item]
    store.add_rows(event_rows([level_event(2.0)]))
    assert store.flush() == 1
    [event] = everything(store)
    assert (event["time"], event["robot"], event["new_level"]) == (2.0, "robot1", 2)


def test_the_exporters_queue_holds_a_whole_fleet_first_heard(tmp_path: Path) -> None:
    # 10,000 robots of 50 components first heard at once: 500,000 `appeared` events before any is written.
    history = EventHistory(EventsConfig(path=str(tmp_path / "events.db")), max_robots=10_000)
    store = history.store
    store.add_rows(event_rows([level_event(1000.0 + i / 1000) for i in range(1000)]) * 500)
    assert store.stats().dropped["queue_full"] == 0
    assert EventHistory(
        EventsConfig(path=str(tmp_path / "small.db")), max_robots=10
    ).store.settings.queue_limit == (DEFAULT_QUEUE_LIMIT)
    store.stop()


def test_a_corrupt_file_degrades_the_store_and_says_so(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    path = tmp_path / "events.db"
    path.write_bytes(b"this is not a database, it is a shopping list\n" * 200)
    store = EventStore(settings(path))
    assert not store.available
    assert store.problem is not None and str(path) in store.problem and "delete it" in store.problem
    assert "events are not being written" in caplog.text
    store.start()
    store.add([level_event(1.0), level_event(2.0)])
    with pytest.raises(EventsUnavailable):
        store.query(EventQuery())
    exposition = metrics(store)
    assert "overseer_events_store_up 0.0" in exposition
    assert 'overseer_events_dropped_total{reason="store_unavailable"} 2.0' in exposition
    store.stop()
    assert path.read_bytes().startswith(b"this is not a database")  # left for the operator to look at


def test_a_degraded_store_still_logs_its_events_without_ids(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    path = tmp_path / "events.db"
    path.write_bytes(b"garbage" * 1000)
    store = EventStore(settings(path, log_events=True))
    with caplog.at_level(logging.INFO, logger="overseer.events"):
        store.add([level_event(7.0)])
    (record,) = [r for r in caplog.records if r.name == "overseer.events"]
    assert record.event["id"] is None and record.event["time"] == 7.0  # type: ignore[attr-defined]
    assert record.event["message"] == "level 2 at 7.0"  # type: ignore[attr-defined]


def test_another_sqlite_database_is_not_taken_for_an_event_database(tmp_path: Path) -> None:
    path = tmp_path / "other.db"
    other = sqlite3.connect(path)
    other.execute("CREATE TABLE inventory (item TEXT)")
    other.commit()
    other.close()
    store = EventStore(settings(path))
    assert not store.available and "not an Overseer event database" in (store.problem or "")


def test_a_missing_directory_degrades_the_store(tmp_path: Path) -> None:
    store = EventStore(settings(tmp_path / "no" / "such" / "dir" / "events.db"))
    assert not store.available
    assert "does not exist" in (store.problem or "")


@contextmanager
def read_only_directory(path: Path) -> Iterator[Path]:
    """A directory nobody can write to: a read-only tmpfs for root, mode 0500 for anyone else."""
    path.mkdir()
    if os.geteuid() == 0:
        subprocess.run(["mount", "-t", "tmpfs", "-o", "ro,size=1m", "tmpfs", str(path)], check=True)
        try:
            yield path
        finally:
            subprocess.run(["umount", str(path)], check=True)
    else:
        path.chmod(0o500)
        try:
            yield path
        finally:
            path.chmod(0o700)


def test_an_unwritable_directory_degrades_the_store(tmp_path: Path) -> None:
    with read_only_directory(tmp_path / "ro") as directory:
        store = EventStore(settings(directory / "events.db"))
        assert not store.available
        assert "cannot open the event database" in (store.problem or "")
        store.add([level_event(1.0)])
        assert store.stats().dropped["store_unavailable"] == 1


def test_a_failing_write_drops_the_batch_counts_it_and_the_next_write_recovers(tmp_path: Path) -> None:
    store = EventStore(settings(tmp_path / "events.db"))
    store.add([level_event(1.0)])
    store.flush()
    assert store._writer is not None
    pages = store._writer.execute("PRAGMA page_count").fetchone()[0]
    store._writer.execute(f"PRAGMA max_page_count = {pages}")  # a full disk, as SQLite sees it
    store.add([level_event(2.0 + i, component="/c" * 500) for i in range(200)])
    assert store.flush() == 0
    stats = store.stats()
    assert stats.dropped["write_error"] == 200 and not stats.up
    assert "overseer_events_store_up 0.0" in metrics(store)
    store._writer.execute("PRAGMA max_page_count = 1073741823")
    store.add([level_event(500.0)])
    assert store.flush() == 1
    assert store.stats().up
    assert [e["time"] for e in store.query(EventQuery())[0]] == [500.0, 1.0]
