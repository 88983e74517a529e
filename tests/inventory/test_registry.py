"""The robots heard, kept in the exporter's SQLite file beside the event history and maintenance windows."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import pytest

from overseer.history.store import EventStore, StoreSettings
from overseer.inventory.registry import RobotRegistry
from overseer.maintenance.store import WindowStore
from overseer.model import RememberedRobot
from overseer.model.events import Event
from overseer.model.maintenance import RobotSelector

HEARD = [
    RememberedRobot("site_a/r1", "dds", 1_700_000_000.5, False, (("/Laser", "l1", 2, 'no "scans"'),)),
    RememberedRobot("r2", "zenoh", 1.0, True),
]


def test_what_is_saved_is_what_a_later_start_loads_and_a_robot_forgotten_is_not(tmp_path: Path) -> None:
    path = str(tmp_path / "overseer-events.db")
    registry = RobotRegistry(path)
    assert registry.save(HEARD)
    registry.close()
    later = RobotRegistry(path)
    assert sorted(later.load()) == sorted(HEARD)
    later.forget("r2")
    assert later.load() == HEARD[:1]
    assert later.save(HEARD[1:])  # a save holds exactly what the fleet heard: r1 was forgotten since
    assert later.load() == HEARD[1:]


def test_components_that_are_not_what_a_save_writes_are_left_out(tmp_path: Path) -> None:
    path = str(tmp_path / "overseer-events.db")
    assert RobotRegistry(path).save(HEARD)
    with sqlite3.connect(path) as database:
        database.execute(
            """UPDATE robots_heard SET components = '[["/a", "", "2", "m"], ["/b", "", 1, "ok"]]'"""
        )
        database.execute("UPDATE robots_heard SET components = '{' WHERE robot = 'r2'")
    assert sorted(robot.components for robot in RobotRegistry(path).load()) == [(), (("/b", "", 1, "ok"),)]


def test_nothing_to_remember_makes_no_file(tmp_path: Path) -> None:
    path = tmp_path / "overseer-events.db"
    registry = RobotRegistry(str(path))
    assert registry.load() == [] and registry.save([])
    registry.forget("r1")
    assert not path.exists()


def test_it_shares_the_file_with_the_event_history_and_the_maintenance_windows(tmp_path: Path) -> None:
    path = str(tmp_path / "overseer-events.db")
    registry = RobotRegistry(path)
    assert registry.save(HEARD)  # made first: the event store must still take the file as its own
    store = EventStore(StoreSettings(path, retention=3600, max_size=10**8))
    assert store.available, store.problem
    store.start()
    store.add([Event(1.0, "r1", "robot_up")])
    store.stop()
    windows = WindowStore(path)
    windows.add(RobotSelector.parse("r1"), 0.0, 10.0, "test", "alice", 0.0)
    assert sorted(RobotRegistry(path).load()) == sorted(HEARD)


def test_a_file_that_is_not_overseers_is_left_alone_and_said_so(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    path = tmp_path / "other.db"
    with sqlite3.connect(path) as other:
        other.execute("CREATE TABLE mine (x)")
    registry = RobotRegistry(str(path))
    assert registry.load() == [] and not registry.save(HEARD)
    assert "not an Overseer event database" in caplog.text
    with sqlite3.connect(path) as other:
        assert [row[0] for row in other.execute("SELECT name FROM sqlite_master")] == ["mine"]


def test_a_directory_that_does_not_exist_remembers_nothing_and_says_why(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    registry = RobotRegistry(str(tmp_path / "absent" / "overseer-events.db"))
    assert registry.problem is not None and "does not exist" in caplog.text
    assert not registry.save(HEARD) and registry.load() == []
