"""Transition detection: every kind of event, with exact times and messages, from a real fleet model."""

from __future__ import annotations

import itertools
import threading

from hypothesis import given, settings
from hypothesis import strategies as st

from overseer.levels import Level
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import FleetLimits, FleetModel
from overseer.model.events import Event
from overseer.model.fleet import LevelChange
from overseer.model.transitions import TransitionDetector
from support.clock import ManualClock
from support.examples import examples

STALE_AFTER, ROBOT_TIMEOUT, EXPIRE_AFTER = 5.0, 10.0, 60.0


class Fleet:
    """A fleet model with a detector attached, collecting what it sends."""

    def __init__(self) -> None:
        """An empty fleet at a fixed time."""
        self.clock = ManualClock()
        limits = FleetLimits(stale_after=STALE_AFTER, robot_timeout=ROBOT_TIMEOUT, expire_after=EXPIRE_AFTER)
        self.model = FleetModel(limits, clock=self.clock)
        self.events: list[Event] = []
        self.detector = TransitionDetector(limits, self.events.extend)
        self.model.set_level_listener(self.detector.on_level_changes)

    def publish(self, robot: str, *statuses: tuple[int, str, str], feed: str = "") -> None:
        """Apply one array of (level, name, message) statuses, each with a voltage key-value."""
        array = DiagnosticArray(
            0, 0, "", tuple(DiagnosticStatus(lv, n, m, "hw", (("voltage", "11.2"),)) for lv, n, m in statuses)
        )
        self.model.apply(robot, array, "dds", feed=feed)

    def advance(self, seconds: float) -> None:
        """Move the clock on."""
        self.clock.now += seconds

    def check(self) -> None:
        """Run the periodic snapshot comparison."""
        self.detector.check(self.model.told_snapshot())

    def take(self) -> list[Event]:
        """The events sent since the last call."""
        events, self.events[:] = list(self.events), []
        return events


def kinds(events: list[Event]) -> list[tuple[str, str | None]]:
    return [(event.kind, event.component) for event in events]


def started_fleet() -> Fleet:
    """robot1 heard twice, a second apart: its period is known."""
    fleet = Fleet()
    fleet.publish("robot1", (0, "/a", "ok"), (0, "/b", "ok"))
    fleet.advance(1)
    fleet.publish("robot1", (0, "/a", "ok"), (0, "/b", "ok"))
    fleet.check()
    fleet.take()
    return fleet


def test_a_first_message_makes_its_components_appear_and_its_robot_up() -> None:
    fleet = Fleet()
    start = fleet.clock.now
    fleet.publish("robot1", (0, "/a", "fine"), (2, "/b", "broken"))
    fleet.check()
    events = fleet.take()
    assert kinds(events) == [("appeared", "/a"), ("appeared", "/b"), ("robot_up", None)]
    appeared = events[1]
    assert appeared == Event(
        start, "robot1", "appeared", "/b", "hw", None, Level.ERROR, "broken", (("voltage", "11.2"),)
    )
    assert events[2] == Event(
        start,
        "robot1",
        "robot_up",
        old_level=None,
        new_level=Level.ERROR,
        message="first diagnostics received",
    )


class JitteryWallClock:
    """A wall clock read the given microseconds after the monotonic one, each read in turn."""

    def __init__(self, monotonic: ManualClock, *late_by_microseconds: float) -> None:
        """Follow `monotonic` 1,000 s ahead, late by each of `late_by_microseconds` in turn, then by 0."""
        self._monotonic = monotonic
        self._late = list(late_by_microseconds)

    def __call__(self) -> float:
        """The time, as read this once."""
        late = self._late.pop(0) if self._late else 0.0
        return self._monotonic.now + 1_000.0 + late * 1e-6


def test_a_robot_up_is_dated_as_the_message_that_brought_it_up_however_the_clocks_were_read() -> None:
    # Under load the wall clock may be read a few microseconds after the monotonic one for one message
    # and not for the next: the robot_up event, dated from the run's monotonic start, must not come
    # before the `appeared` of the message that began the run (events are listed by time).
    monotonic = ManualClock()
    limits = FleetLimits(stale_after=STALE_AFTER, robot_timeout=ROBOT_TIMEOUT, expire_after=EXPIRE_AFTER)
    model = FleetModel(limits, clock=monotonic, wall_clock=JitteryWallClock(monotonic, 40.0))
    sent: list[Event] = []
    detector = TransitionDetector(limits, sent.extend)
    model.set_level_listener(detector.on_level_changes)
    array = DiagnosticArray(0, 0, "", (DiagnosticStatus(0, "drive: Motor", "spinning", "m1", ()),))
    for _ in range(3):
        model.apply("robot_b", array, "dds")
        monotonic.now += 1.0
    detector.check(model.told_snapshot())
    appeared, up = sent
    assert (appeared.kind, up.kind) == ("appeared", "robot_up")
    assert up.time == appeared.time == monotonic.now - 3.0 + 1_000.0 + 40e-6


def test_a_level_change_is_one_event_with_its_message_values_and_exact_time() -> None:
    fleet = started_fleet()
    fleet.advance(0.37)
    fleet.publish("robot1", (2, "/a", "motor stalled"), (0, "/b", "ok"))
    at = fleet.clock.now
    fleet.check()
    assert fleet.take() == [
        Event(
            at, "robot1", "level", "/a", "hw", Level.OK, Level.ERROR, "motor stalled", (("voltage", "11.2"),)
        )
    ]


def test_flapping_within_a_second_records_every_change_between_two_checks() -> None:
    fleet = started_fleet()
    for level, message in [(2, "spike"), (0, "ok"), (1, "warm"), (0, "ok")]:
        fleet.advance(0.1)
        fleet.publish("robot1", (level, "/a", message), (0, "/b", "ok"))
    fleet.check()
    events = fleet.take()
    assert [(e.old_level, e.new_level, e.message) for e in events] == [
        (Level.OK, Level.ERROR, "spike"),
        (Level.ERROR, Level.OK, "ok"),
        (Level.OK, Level.WARN, "warm"),
        (Level.WARN, Level.OK, "ok"),
    ]
    assert [e.time for e in events] == sorted(e.time for e in events) and len({e.time for e in events}) == 4


def test_a_new_message_or_value_at_the_same_level_is_no_event() -> None:
    fleet = started_fleet()
    fleet.advance(1)
    fleet.publish("robot1", (0, "/a", "still ok, other words"), (0, "/b", "ok"))
    fleet.check()
    assert fleet.take() == []


def test_a_partial_apply_reports_its_level_changes_too() -> None:
    fleet = Fleet()
    statuses = (DiagnosticStatus(0, "/a", "ok", "", ()), DiagnosticStatus(0, "/b", "ok", "", ()))
    applied = fleet.model.apply_array("robot1", DiagnosticArray(0, 0, "", statuses), "dds")
    assert applied.revision is not None
    fleet.take()
    fleet.advance(0.5)
    revision = fleet.model.apply_changes(
        "robot1", applied.revision, [(1, DiagnosticStatus(1, "/b", "hot", "", ()))], "dds"
    )
    assert revision == applied.revision + 1
    assert fleet.take() == [Event(fleet.clock.now, "robot1", "level", "/b", "", Level.OK, Level.WARN, "hot")]


def test_republishing_the_same_array_is_no_event_over_many_checks() -> None:
    fleet = started_fleet()
    for _ in range(20):
        fleet.advance(1)
        assert fleet.model.touch("robot1", "dds")
        fleet.check()
    assert fleet.take() == []


def test_a_silent_robot_goes_down_once_at_its_timeout_and_comes_back_up() -> None:
    fleet = started_fleet()
    fleet.publish("robot1", (1, "/a", "warm"), (0, "/b", "ok"))
    last = fleet.clock.now
    fleet.take()
    for _ in range(int(ROBOT_TIMEOUT) - 1):  # components go STALE at 5 s: implied, not one event each
        fleet.advance(1)
        fleet.check()
    assert fleet.take() == []
    fleet.advance(1.5)
    fleet.check()
    assert fleet.take() == [
        Event(
            last + ROBOT_TIMEOUT,
            "robot1",
            "robot_down",
            old_level=Level.WARN,
            new_level=Level.STALE,
            message="no diagnostics received for 10 s",
        )
    ]
    fleet.advance(5)
    fleet.check()
    assert fleet.take() == []
    fleet.publish("robot1", (1, "/a", "warm"), (0, "/b", "ok"))
    fleet.check()
    assert fleet.take() == [
        Event(
            fleet.clock.now,
            "robot1",
            "robot_up",
            old_level=Level.STALE,
            new_level=Level.WARN,
            message="diagnostics received again",
        )
    ]


def test_a_component_left_out_goes_missing_at_its_bound_and_appears_when_updated_again() -> None:
    fleet = started_fleet()
    last_report = fleet.clock.now
    for _ in range(4):  # left out of the arrays: no event while it is within its bound
        fleet.advance(1)
        fleet.publish("robot1", (0, "/a", "ok"))
        fleet.check()
    assert fleet.take() == []
    for _ in range(3):
        fleet.advance(1)
        fleet.publish("robot1", (0, "/a", "ok"))
        fleet.check()
    assert fleet.take() == [
        Event(
            last_report + STALE_AFTER,
            "robot1",
            "missing",
            "/b",
            "hw",
            Level.OK,
            Level.STALE,
            "not updated for 5 s",
        )
    ]
    fleet.advance(1)
    fleet.publish("robot1", (0, "/a", "ok"), (2, "/b", "back, broken"))
    back = fleet.clock.now
    fleet.check()
    events = fleet.take()
    assert kinds(events) == [("level", "/b"), ("appeared", "/b")]
    assert (events[0].old_level, events[0].new_level, events[0].message) == (
        Level.OK,
        Level.ERROR,
        "back, broken",
    )
    assert (events[1].time, events[1].old_level, events[1].new_level) == (back, None, Level.ERROR)


def test_nodes_sharing_a_robots_topic_and_start_up_arrays_give_no_missing_or_appeared() -> None:
    # Two diagnostic_updater nodes on one robot: partial arrays, start-up arrays of one status each.
    fleet = Fleet()
    fleet.publish("robot1", (0, "drive: a", "Node starting up"), feed="drive")
    fleet.publish("robot1", (0, "camera: b", "Node starting up"), feed="camera")
    fleet.check()
    assert kinds(fleet.take()) == [("appeared", "drive: a"), ("appeared", "camera: b"), ("robot_up", None)]
    for second in range(120):
        fleet.advance(0.5)
        fleet.publish("robot1", (0, "drive: a", "ok"), (0, "drive: c", "ok"), feed="drive")
        if second == 60:  # a task added late: its start-up array, then it is in every array
            fleet.publish("robot1", (0, "camera: d", "Node starting up"), feed="camera")
        fleet.advance(0.5)
        names = [(0, "camera: b", "ok")] + ([(0, "camera: d", "ok")] if second >= 60 else [])
        fleet.publish("robot1", *names, feed="camera")
        fleet.check()
    assert kinds(fleet.take()) == [("appeared", "drive: c"), ("appeared", "camera: d")]


def test_forgotten_components_and_robots_expire() -> None:
    fleet = started_fleet()
    fleet.publish("robot2", (0, "/x", "ok"))
    fleet.check()
    fleet.take()
    for _ in range(int(EXPIRE_AFTER) + 2):
        fleet.advance(1)
        fleet.publish("robot1", (0, "/a", "ok"))  # /b silent from here on; robot2 silent altogether
        fleet.check()
    fleet.model.expire()
    fleet.check()
    events = fleet.take()
    assert ("expired", "/b") in kinds(events)
    robot2 = [e for e in events if e.robot == "robot2"]
    assert [(e.kind, e.component, e.message) for e in robot2][-1] == (
        "expired",
        None,
        "forgotten after 60 s of silence",
    )
    assert [e.kind for e in robot2] == ["robot_down", "expired"]


def test_a_robot_forgotten_and_heard_again_before_the_next_check_expires_then_comes_up_anew() -> None:
    fleet = started_fleet()
    fleet.publish("robot2", (2, "/x", "broken"))
    fleet.check()
    fleet.take()
    for _ in range(int(EXPIRE_AFTER) + 2):
        fleet.advance(1)
        fleet.publish("robot1", (0, "/a", "ok"), (0, "/b", "ok"))
        fleet.check()
    assert [e.kind for e in fleet.take() if e.robot == "robot2"] == ["robot_down"]
    fleet.model.expire()
    forgotten_at = fleet.clock.now
    fleet.advance(0.5)
    fleet.publish("robot2", (0, "/x", "fine"))  # within the same second: the detector never saw it gone
    fleet.check()
    robot2 = [e for e in fleet.take() if e.robot == "robot2"]
    assert [(e.kind, e.component) for e in robot2] == [
        ("appeared", "/x"),
        ("expired", None),
        ("robot_up", None),
    ]
    appeared, expired, up = robot2
    assert expired.time == forgotten_at and expired.message == "forgotten after 60 s of silence"
    assert appeared.old_level is None and appeared.new_level is Level.OK
    assert (up.old_level, up.new_level, up.message) == (None, Level.OK, "first diagnostics received")
    assert up.time == fleet.clock.now
    fleet.advance(1)
    fleet.publish("robot2", (0, "/x", "fine"))
    fleet.check()
    assert [e for e in fleet.take() if e.robot == "robot2"] == []


def test_a_robot_known_but_never_heard_is_no_event_until_its_first_message() -> None:
    fleet = Fleet()
    assert fleet.model.register("robot1", "dds")
    fleet.check()
    fleet.advance(30)
    fleet.check()
    assert fleet.take() == []
    fleet.publish("robot1", (0, "/a", "ok"))
    fleet.check()
    assert kinds(fleet.take()) == [("appeared", "/a"), ("robot_up", None)]
    assert fleet.model.register("robot2", "dds")
    fleet.check()
    fleet.advance(EXPIRE_AFTER + 1)
    assert fleet.model.expire() == ["robot1", "robot2"]
    fleet.check()
    assert [(e.robot, e.kind) for e in fleet.take()] == [("robot1", "expired")]  # robot2 was never heard


def test_the_model_without_a_listener_sends_nothing() -> None:
    fleet = Fleet()
    fleet.model.set_level_listener(None)
    fleet.publish("robot1", (0, "/a", "ok"))
    fleet.advance(0.2)
    fleet.publish("robot1", (2, "/a", "bad"))
    assert fleet.take() == []


@settings(max_examples=examples(200), deadline=None)
@given(
    st.lists(
        st.dictionaries(st.sampled_from(["/a", "/b", "/c"]), st.integers(0, 2), min_size=1),
        min_size=1,
        max_size=30,
    )
)
def test_level_events_replay_to_the_models_levels_and_change_counts(arrays: list[dict[str, int]]) -> None:
    fleet = Fleet()
    for statuses in arrays:
        fleet.advance(0.1)
        fleet.publish("robot1", *((level, name, f"at {level}") for name, level in statuses.items()))
    events = fleet.take()
    robot = fleet.model.snapshot().robots[0]
    for key, component in robot.components.items():
        mine = [e for e in events if e.component == key[0]]
        assert mine[0].kind == "appeared" and all(e.kind == "level" for e in mine[1:])
        assert mine[-1].new_level is component.level and mine[-1].message == component.message
        assert len(mine) - 1 == component.level_changes  # as ros_diagnostics_level_changes_total counts
        assert all(a.new_level is b.old_level for a, b in itertools.pairwise(mine))


def test_a_publisher_that_left_is_a_robot_down_at_the_check_not_after_the_timeout() -> None:
    fleet = Fleet()
    fleet.publish("r1", (0, "/a", "fine"))
    fleet.check()
    fleet.take()
    fleet.advance(2)
    fleet.model.publisher_left("r1")  # as Zenoh liveliness or DDS discovery reports it
    left = fleet.clock.now
    fleet.advance(0.7)
    fleet.check()
    [down] = fleet.take()
    assert (down.kind, down.time, down.message) == ("robot_down", left, "its diagnostics publisher left")
    fleet.advance(1)  # a new publisher appears: nothing until it sends something
    fleet.check()
    assert fleet.take() == []
    fleet.publish("r1", (0, "/a", "fine"))
    back = fleet.clock.now
    fleet.advance(0.6)
    fleet.check()
    [up] = fleet.take()
    assert (up.kind, up.time) == ("robot_up", back) and down.time < up.time


def test_a_robot_up_and_down_between_two_checks_is_both_events_at_their_times() -> None:
    fleet = Fleet()
    fleet.check()
    fleet.publish("r1", (0, "/a", "fine"))
    first = fleet.clock.now
    fleet.advance(0.3)
    fleet.model.publisher_left("r1")  # a node that came and went within a second
    left = fleet.clock.now
    fleet.advance(0.5)
    fleet.check()
    assert [(e.kind, e.time) for e in fleet.take() if e.kind != "appeared"] == [
        ("robot_up", first),
        ("robot_down", left),
    ]
    fleet.advance(2)
    fleet.publish("r1", (0, "/a", "fine"))  # back: up again
    back = fleet.clock.now
    fleet.check()
    fleet.advance(0.2)
    fleet.model.publisher_left("r1")
    gone = fleet.clock.now
    fleet.advance(0.2)
    fleet.publish("r1", (0, "/a", "fine"))  # a restart between two checks: down and up again
    again = fleet.clock.now
    fleet.advance(0.5)
    fleet.check()
    assert [(e.kind, e.time) for e in fleet.take()] == [
        ("robot_up", back),
        ("robot_down", gone),
        ("robot_up", again),
    ]


def test_a_check_that_sees_an_apply_sends_its_events_after_the_applys_own() -> None:
    """The detector's thread may take its snapshot while an ingest thread is still telling the listener."""
    fleet = Fleet()
    telling, go_on = threading.Event(), threading.Event()

    def slow_listener(robot: str, at: float, changes: list[LevelChange]) -> None:
        telling.set()
        go_on.wait(10)
        fleet.detector.on_level_changes(robot, at, changes)

    fleet.model.set_level_listener(slow_listener)
    ingest = threading.Thread(target=fleet.publish, args=("r1", (0, "/Motor", "spinning")))
    ingest.start()
    assert telling.wait(10)
    detector = threading.Thread(target=fleet.check)
    detector.start()
    detector.join(0.3)
    assert detector.is_alive(), "the check went on while the apply it saw was still being told"
    go_on.set()
    ingest.join(10)
    detector.join(10)
    assert [(event.kind, event.component) for event in fleet.take()] == [
        ("appeared", "/Motor"),
        ("robot_up", None),
    ]
