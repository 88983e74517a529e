"""A stopped exporter has closed every connection to its SQLite file, before the process ends.

SQLite removes the write-ahead log when the last connection closes; one left open (the maintenance
windows', the robots heard's) leaves it to the interpreter's exit, which a hung thread can skip.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from overseer.inventory.registry import RobotRegistry
from overseer.maintenance.store import StoreUnavailable, WindowStore
from overseer.model import RememberedRobot
from overseer.model.maintenance import RobotSelector
from testbed.in_process import in_process_exporter, publish


def leftovers(database: Path) -> list[str]:
    """The write-ahead log and shared-memory files still beside `database`."""
    return [path.name for path in (Path(f"{database}-wal"), Path(f"{database}-shm")) if path.exists()]


def test_a_stopped_exporter_leaves_no_write_ahead_log_while_its_process_lives(tmp_path: Path) -> None:
    database = tmp_path / "events.db"
    with in_process_exporter(tmp_path) as running:
        publish(running, "robot1", (2, "/lidar", "no scans"))
        assert running.memory.save()
        assert leftovers(database)  # in WAL mode while it runs
    assert leftovers(database) == []


def test_a_registry_closed_opens_its_file_no_more(tmp_path: Path) -> None:
    database = tmp_path / "events.db"
    registry = RobotRegistry(str(database))
    robot = RememberedRobot("robot1", "dds", 1.0, False)
    assert registry.save([robot])
    registry.close()
    assert not registry.save([robot])  # a save that was under way at stop
    assert leftovers(database) == []


def test_a_closed_window_store_refuses_rather_than_say_there_is_no_window(tmp_path: Path) -> None:
    """A scrape on a kept-alive connection while the exporter stops must not see maintenance end."""
    store = WindowStore(str(tmp_path / "events.db"))
    store.add(RobotSelector("robot1"), 0.0, 4e9, "swap the lidar", "ops", 0.0)
    assert len(store.windows(1.0)) == 1
    store.close()
    with pytest.raises(StoreUnavailable, match="closed"):
        store.windows(1.0)
    with pytest.raises(StoreUnavailable, match="closed"):
        store.effects("icinga2")
    assert leftovers(tmp_path / "events.db") == []
