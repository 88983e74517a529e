"""Maintenance windows: which robots they cover, when, recurring ones through midnight and DST, who owns them.

Pure and on a real SQLite file: the schedule with a hand-moved clock, no exporter.
"""

from __future__ import annotations

import datetime
from pathlib import Path
from zoneinfo import ZoneInfo

import pytest

from overseer.config import ConfigError, load_config
from overseer.config.maintenance import MaintenanceConfig
from overseer.maintenance.schedule import MaintenanceSchedule, WindowError
from overseer.maintenance.store import StoreUnavailable, WindowStore
from overseer.model.events import Event
from overseer.model.maintenance import RobotSelector
from support.clock import ManualClock

BERLIN = ZoneInfo("Europe/Berlin")


def clock_at(moment: datetime.datetime) -> ManualClock:
    """A hand-moved clock set to `moment`."""
    return ManualClock(moment.timestamp())


def local(text: str) -> float:
    """Unix time of a Berlin wall-clock time `YYYY-MM-DD HH:MM`."""
    return datetime.datetime.strptime(text, "%Y-%m-%d %H:%M").replace(tzinfo=BERLIN).timestamp()


def config(tmp_path: Path, text: str) -> MaintenanceConfig:
    path = tmp_path / "overseer.yml"
    path.write_text(text, encoding="utf-8")
    return load_config(path, environ={}).maintenance


NIGHTS = (
    "maintenance:\n  windows:\n"
    "    - {robots: site_a/, from: '22:00', to: '06:00', time_zone: Europe/Berlin, comment: parked}\n"
)


@pytest.mark.parametrize(
    ("text", "robot", "covered"),
    [
        ("robot7", "robot7", True),
        ("robot7", "robot70", False),
        ("/site_a/robot7", "site_a/robot7", True),
        ("site_a/", "site_a/robot7", True),
        ("site_a/", "site_a", False),
        ("site_a/", "site_ab/robot1", False),
        ("site_a/", "site_a/deep/robot2", True),
    ],
)
def test_a_window_covers_one_robot_by_name_or_a_namespace_by_prefix(
    text: str, robot: str, covered: bool
) -> None:
    assert RobotSelector.parse(text).matches(robot) is covered


@pytest.mark.parametrize(
    "text", ["", "/", "a//b", "robot 1", "../etc", "robot\n1", "x" * 300, "ロボット", None, 7]
)
def test_a_robot_selector_refuses_what_no_robot_is_named(text: object) -> None:
    with pytest.raises(ValueError, match="expected a robot name"):
        RobotSelector.parse(text)


def test_a_nightly_window_runs_past_midnight_in_its_time_zone(tmp_path: Path) -> None:
    clock = clock_at(datetime.datetime(2026, 11, 23, 23, 0, tzinfo=BERLIN))
    schedule = MaintenanceSchedule(config(tmp_path, NIGHTS), None, clock=clock)
    [window] = schedule.active(clock.now)
    assert (window.start, window.until) == (local("2026-11-23 22:00"), local("2026-11-24 06:00"))
    assert window.recurring and window.author == "configuration" and window.comment == "parked"
    state = schedule.state("site_a/robot7", schedule.active(clock.now))
    assert state is not None and state.until == local("2026-11-24 06:00")
    assert schedule.state("site_b/robot1", schedule.active(clock.now)) is None
    assert schedule.active(local("2026-11-24 12:00")) == []
    assert schedule.active(local("2026-11-24 05:59"))[0].start == local("2026-11-23 22:00")


def test_a_night_across_the_spring_clock_change_is_an_hour_shorter(tmp_path: Path) -> None:
    clock = clock_at(
        datetime.datetime(2027, 3, 27, 23, 0, tzinfo=BERLIN)
    )  # clocks go forward at 02:00 on the 28th
    [window] = MaintenanceSchedule(config(tmp_path, NIGHTS), None, clock=clock).active(clock.now)
    assert window.until - window.start == 7 * 3600


def test_a_window_on_weekdays_only_skips_the_weekend(tmp_path: Path) -> None:
    text = (
        "maintenance:\n  windows:\n"
        "    - {robots: r1, days: [mon, tue, wed, thu, fri], from: '12:00', to: '13:00'}\n"
    )
    schedule = MaintenanceSchedule(config(tmp_path, text), None)
    monday = datetime.datetime(2026, 11, 23, 12, 30, tzinfo=datetime.timezone.utc).timestamp()
    assert len(schedule.active(monday)) == 1
    assert schedule.active(monday + 5 * 86400) == []  # Saturday


@pytest.mark.parametrize(
    ("window", "message"),
    [
        (
            "{robots: 'a b', from: '22:00', to: '06:00'}",
            "maintenance.windows[0].robots: expected a robot name",
        ),
        (
            "{robots: r1, from: '25:00', to: '06:00'}",
            "maintenance.windows[0].from: expected a time of day HH:MM",
        ),
        ("{robots: r1, from: '22:00', to: '22:00'}", "maintenance.windows[0].to: must differ"),
        (
            "{robots: r1, from: '22:00', to: '06:00', time_zone: Mars/Olympus}",
            "time_zone: expected a time zone",
        ),
        (
            "{robots: r1, from: '22:00', to: '06:00', days: [someday]}",
            "maintenance.windows[0].days: expected a list",
        ),
        ("{robots: r1, from: '22:00', to: '06:00', every: day}", "maintenance.windows[0].every: unknown key"),
    ],
)
def test_a_bad_recurring_window_is_one_error_naming_it(tmp_path: Path, window: str, message: str) -> None:
    with pytest.raises(ConfigError) as raised:
        config(tmp_path, f"maintenance:\n  windows:\n    - {window}\n")
    assert message in str(raised.value)


def test_open_and_end_a_window_tell_the_history_with_author_and_comment(tmp_path: Path) -> None:
    clock = clock_at(datetime.datetime(2026, 11, 23, 10, 0, tzinfo=datetime.timezone.utc))
    events: list[Event] = []
    schedule = MaintenanceSchedule(MaintenanceConfig(), None, events.extend, clock)
    window = schedule.open(RobotSelector.parse("robot3"), None, clock.now + 7200, " battery swap ", "alice")
    assert window.key == "w1" and window.comment == "battery swap" and window.active(clock.now)
    assert [(e.kind, e.robot, e.message, dict(e.values)["author"]) for e in events] == [
        ("maintenance_start", "robot3", "battery swap", "alice")
    ]
    clock.now += 600
    ended = schedule.end("w1", "bob")
    assert ended.until == clock.now and not ended.active(clock.now)
    assert [event.kind for event in events] == ["maintenance_start", "maintenance_end"]
    assert events[-1].time == clock.now
    with pytest.raises(WindowError, match="is over already"):
        schedule.end("w1", "bob")
    with pytest.raises(KeyError):
        schedule.end("w99", "bob")


def test_a_window_that_starts_later_is_told_when_it_starts(tmp_path: Path) -> None:
    clock = clock_at(datetime.datetime(2026, 11, 23, 10, 0, tzinfo=datetime.timezone.utc))
    events: list[Event] = []
    schedule = MaintenanceSchedule(MaintenanceConfig(), None, events.extend, clock)
    schedule.open(RobotSelector.parse("site_b/"), clock.now + 3600, clock.now + 7200, "shift change", "ops")
    assert events == [] and schedule.active(clock.now) == []
    clock.now += 3600
    schedule.check()
    assert [(event.kind, event.time) for event in events] == [("maintenance_start", clock.now)]
    assert schedule.state("site_b/r1", schedule.active(clock.now)) is not None


@pytest.mark.parametrize(
    ("start", "end", "comment", "message"),
    [
        (-3600.0, 3600.0, "x", "start: must not be in the past"),
        (None, -1.0, "x", "end: must be after the start"),
        (None, 32 * 86400.0, "x", "end: a window lasts at most 31 days"),
        (400 * 86400.0, 401 * 86400.0, "x", "start: must be within a year"),
        (None, 3600.0, "   ", "comment: expected 1 to 1000 characters"),
        (None, 3600.0, "line\nbreak", "comment: expected 1 to 1000 characters with no control characters"),
        (None, 3600.0, "x" * 1001, "comment: expected 1 to 1000 characters"),
        (None, float("nan"), "x", "end: must be after the start"),
    ],
)
def test_a_window_that_makes_no_sense_is_refused_naming_the_field(
    start: float | None, end: float, comment: str, message: str
) -> None:
    clock = clock_at(datetime.datetime(2026, 11, 23, 10, 0, tzinfo=datetime.timezone.utc))
    schedule = MaintenanceSchedule(MaintenanceConfig(), None, clock=clock)
    with pytest.raises(WindowError, match=message):
        schedule.open(
            RobotSelector.parse("r1"),
            None if start is None else clock.now + start,
            clock.now + end,
            comment,
            "a",
        )


def test_windows_and_their_effects_survive_a_restart_in_the_database(tmp_path: Path) -> None:
    path = str(tmp_path / "overseer-events.db")
    clock = clock_at(datetime.datetime(2026, 11, 23, 10, 0, tzinfo=datetime.timezone.utc))
    first = MaintenanceSchedule(MaintenanceConfig(), WindowStore(path), clock=clock)
    kept = first.open(RobotSelector.parse("robot1"), None, clock.now + 3600, "repair", "alice")
    ended = first.open(RobotSelector.parse("robot2"), None, clock.now + 3600, "swap", "alice")
    first.end(ended.key, "alice")
    assert first.store is not None
    first.store.keep_effect(kept.key, "alertmanager", "", "silence-1")
    again = MaintenanceSchedule(MaintenanceConfig(), WindowStore(path), clock=clock)
    assert [window.key for window in again.active(clock.now)] == [kept.key]
    assert again.store is not None and again.store.effects("alertmanager") == {(kept.key, ""): "silence-1"}


def test_a_database_that_is_not_overseers_is_refused_with_its_reason(tmp_path: Path) -> None:
    import sqlite3

    other = tmp_path / "other.db"
    sqlite3.connect(other).execute("CREATE TABLE mine (x)").connection.commit()
    with pytest.raises(StoreUnavailable, match="not an Overseer event database"):
        WindowStore(str(other))
    with pytest.raises(StoreUnavailable, match="does not exist"):
        WindowStore(str(tmp_path / "missing" / "x.db"))
