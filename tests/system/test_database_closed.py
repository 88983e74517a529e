"""A stopped exporter has closed every connection to its SQLite file, before the process ends.

SQLite removes the write-ahead log when the last connection closes; one left open (the maintenance
windows', the robots heard's) leaves it to the interpreter's exit, which a hung thread can skip.
"""

from __future__ import annotations

from pathlib import Path

from overseer.inventory.registry import RobotRegistry
from overseer.model import RememberedRobot
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
